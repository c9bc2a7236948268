"""Scope sampling by PDO on the demo plant over a real virtual bus: the plan (which TPDOs, the bus share, refusals in
words), a 1 ms recording of node 7 during a profile-position move checked frame by frame against the TPDO frames on
the bus (a second python-can bus on the channel), the restore read back, a node that stops sending, and the
confirmation a recording needs."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Iterator

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, Conflict, InvalidValue
from drivebench.protocol.canopen.network import frames_of
from drivebench.services.bus.sessions import Session
from drivebench.services.control import motion
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.params import node_lease
from drivebench.services.params import writes as parameters
from drivebench.services.params.node_lease import NodeLeased
from drivebench.services.params.write_context import WriteContext, Writer
from drivebench.services.pdos import pdo
from drivebench.services.scope import pdo_source, restore_record
from drivebench.services.scope.pdo_plan import ScopePlan, plan_recording
from drivebench.services.scope.pdo_source import PdoScopeSource
from drivebench.services.scope.source import ScopeChannel, ScopeEvent, ScopeFrame
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage import database
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.transport.busload import frame_bits
from tests.confirming import confirmed_call
from tests.conftest import DEMO_PLANT, frames_in_bus_order, fresh_channel, wait_until
from tests.services.test_motion import AXIS, Axis
from tests.write_contexts import SERVICE, as_writer

POSITION, VELOCITY = ScopeChannel(AXIS, "0x6064"), ScopeChannel(AXIS, "0x606C")
TPDO3 = 0x380 + AXIS


def _wait_operational(session: Session, nodes: tuple[int, ...]) -> None:
    assert wait_until(lambda: all(session.nmt_state(node)[1] for node in nodes), 10), "heartbeats"


def confirmed_ctx(plan: ScopePlan) -> WriteContext:
    """The context of a client that repeats what the 428 asked for."""
    needed = pdo_source.confirmation(plan)
    assert needed is not None, plan.texts()
    node, _what, values = needed
    return SERVICE.confirming(Confirmation("all" if node is None else node, values))


def settings_of(runner: asyncio.Runner, session: Session, node: int, number: int) -> dict[str, int]:
    values = {}
    for index, subs in ((0x1800 + number - 1, (1, 2, 3, 5)), (0x1A00 + number - 1, (0, 1, 2, 3, 4))):
        for sub in subs:
            values[f"0x{index:04X}.{sub}"] = runner.run(pdo.read_u32(session, node, index, sub))
    for index in (0x1005, 0x1006):
        if pdo.node_catalog(session, node).by_address(index, 0):
            values[f"0x{index:04X}"] = runner.run(pdo.read_u32(session, node, index, 0))
    return values


def test_the_plan_maps_free_tpdos_and_says_which_nodes_are_polled(
        plant_session: tuple[asyncio.Runner, Session]) -> None:
    runner, session = plant_session
    channels = [POSITION, VELOCITY, ScopeChannel(3, "0x6041", bit=2), ScopeChannel(3, "0x6044"),
                ScopeChannel(5, "C00868/1")]
    plan = runner.run(plan_recording(session, channels, 0.001))
    assert [(t.node, t.number, t.cob_id, [e.ref for e in t.entries]) for t in plan.tpdos] == [
        (7, 3, TPDO3, ["0x6064", "0x606C"]), (3, 5, 0x283, ["0x6041", "0x6044"])]
    # TPDO1/2 of node 7 are valid and mapped (in use); TPDO3 is invalid (free). The 8400 motec's TPDOs are valid
    # and carry the port words (static mapping): no free TPDO, so it is polled, with why.
    assert [p.node for p in plan.polling] == [5]
    assert "no free TPDO" in plan.polling[0].reason
    assert plan.slots[2] is not None and plan.slots[2].bit == 2 and plan.slots[2].bits == 16  # the whole word
    assert plan.slots[4] is None
    # SYNC (0x080, no data) + TPDO3 of node 7 (8 bytes) + TPDO5 of node 3 (4 bytes), each counted as the monitor does
    bits = frame_bits(0x080) + frame_bits(TPDO3, bytes(8)) + frame_bits(0x283, bytes(4))
    assert plan.bits_per_sync == bits
    assert plan.bus_share == pytest.approx(100 * bits / (0.001 * 500_000))
    assert any(f"{plan.bus_share:.1f} %" in text for text in plan.texts())


def test_a_node_whose_heartbeat_came_late_is_still_sampled_by_pdo(
        plant_session: tuple[asyncio.Runner, Session], plant: Plant) -> None:
    """A loaded host handles heartbeats late and counts a healthy node's heartbeat as lost: it still answers SDO, so
    the plan maps its TPDO and starts it (was: polled, "not operational (NMT state: Heartbeat lost)")."""
    runner, session = plant_session
    assert wait_until(lambda: session.heartbeat(AXIS).expected_period_s() is not None, 10), "two heartbeats"
    plant.nodes[AXIS].store.set(0x1017, 0, 60_000)  # the next heartbeat a minute late: none handled
    assert wait_until(lambda: session.nmt_state(AXIS)[0] == "Heartbeat lost", 20), session.nmt_state(AXIS)
    plan = runner.run(plan_recording(session, [POSITION], 0.01))
    assert [(t.node, t.number) for t in plan.tpdos] == [(AXIS, 3)], plan.texts()
    assert plan.start_nodes == (AXIS,) and not plan.polling


def test_the_micromaster_panel_channels_are_mapped_in_its_mapping_sequence(
        plant_session: tuple[asyncio.Runner, Session]) -> None:
    """The Control tab's panel asks for speed 0x6044, torque 0x6077 and the status word 0x6041: neither that order
    nor the index order is the MICROMASTER's TPDO mapping sequence (status word 1, torque 5, speed 6: manual
    MICROMASTER 420/430/440 CANopen Option Module, Issue 01/05, ch. 5.4/5.6, the profile's pdo_rules), which it
    refuses with an EMCY. They used to be polled ("PDO rules do not accept this mapping in TPDO5"); the plan now
    orders them as the device needs."""
    runner, session = plant_session
    channels = [ScopeChannel(3, "0x6044"), ScopeChannel(3, "0x6077"), ScopeChannel(3, "0x6041")]
    plan = runner.run(plan_recording(session, channels, 0.02))
    assert plan.polling == ()
    assert [(t.node, t.number, [e.ref for e in t.entries]) for t in plan.tpdos] == [
        (3, 5, ["0x6041", "0x6077", "0x6044"])]
    assert [(s.offset, s.bits) for s in plan.slots if s is not None] == [(32, 16), (16, 16), (0, 16)]


def test_the_8400_motec_is_polled_because_its_tpdos_send_the_static_port_words(
        plant_session: tuple[asyncio.Runner, Session]) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [ScopeChannel(5, "C00868/2")], 0.02))
    assert [p.node for p in plan.polling] == [5]
    assert plan.polling[0].reason == (
        "it has no free TPDO: TPDO1 sends the device's static mapping (C00868/1, C00868/2, C00868/3, C00868/4); "
        "TPDO2 sends the device's static mapping (C00868/5, C00868/6, C00868/7, C00868/8).")


def test_refusals_in_words(plant_session: tuple[asyncio.Runner, Session]) -> None:
    runner, session = plant_session
    with pytest.raises(InvalidValue, match=r"need 2 TPDOs .* it has 1 free"):
        runner.run(plan_recording(session, [POSITION, VELOCITY, ScopeChannel(AXIS, "0x6077"),
                                            ScopeChannel(AXIS, "0x60F4")], 0.001))
    with pytest.raises(InvalidValue, match="cannot be sampled by PDO"):
        runner.run(plan_recording(session, [ScopeChannel(AXIS, "0x6065")], 0.01))
    with pytest.raises(InvalidValue, match="at least 1 ms"):
        runner.run(plan_recording(session, [POSITION], 0.0005))


@pytest.fixture
def slow_bus(registry: ProfileRegistry) -> Iterator[tuple[asyncio.Runner, Session]]:
    """The demo plant at 125 kbit/s."""
    plant = Plant(PlantFile.load(DEMO_PLANT), registry.get, bus=f"virtual:{fresh_channel()}@125000",
                  latency="0ms").start()
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    session = runner.run(manager.open(plant.spec, "slow"))
    for node in plant.nodes.values():
        session.add_node(node.node_id, node.profile.id)
    yield runner, session
    runner.run(manager.close_all())
    runner.close()
    plant.stop()


def test_a_recording_that_would_overload_the_bus_is_refused_with_the_period_that_fits(
        slow_bus: tuple[asyncio.Runner, Session]) -> None:
    runner, session = slow_bus
    with pytest.raises(InvalidValue) as refused:
        runner.run(plan_recording(session, [POSITION, VELOCITY], 0.001))
    text = str(refused.value.detail)
    assert "a bus share of" in text and "80 % at most" in text and "Choose a period of" in text
    assert runner.run(plan_recording(session, [POSITION, VELOCITY], 0.002)).bus_share < 80


@pytest.fixture
def db(app_db_url: str) -> str:
    """A database of the test's own with the schema (the restore records)."""
    database.upgrade_to_head(app_db_url)
    return app_db_url


class Recorder:
    def __init__(self) -> None:
        self.frames: list[ScopeFrame] = []
        self.events: list[ScopeEvent] = []


def test_starting_needs_the_confirmation_naming_the_node_and_values(
        plant_session: tuple[asyncio.Runner, Session]) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION, VELOCITY], 0.001))
    before = settings_of(runner, session, AXIS, 3)
    with pytest.raises(ConfirmationRequired) as asked:
        runner.run(PdoScopeSource(session, plan, SERVICE).start(print, print))
    assert asked.value.node == AXIS
    assert asked.value.values == {"SYNC period [ms]": 1, "TPDO nodes": [AXIS], "NMT start": [AXIS]}
    assert settings_of(runner, session, AXIS, 3) == before  # nothing was changed


def _wire_samples(frames: list[can.Message]) -> list[tuple[int, bytes]]:
    """Node 7's TPDO3 frames in bus order, each with the number of the newest SYNC before it on the bus."""
    count, found = -1, []
    for msg in frames:
        if msg.arbitration_id == 0x080:
            count += 1
        elif msg.arbitration_id == TPDO3 and count >= 0:
            found.append((count, bytes(msg.data)))
    return found


def test_a_1_ms_recording_of_node_7_during_a_move_equals_the_frames_on_the_bus(
        plant_session: tuple[asyncio.Runner, Session], plant: Plant, wire: can.BusABC, db: str) -> None:
    runner, session = plant_session
    with Axis(runner, session, plant).kept_alive() as axis:  # a loaded run's steps outlast the guard's 2 s
        axis.enable()
        axis.home(35)
        plan = runner.run(plan_recording(session, [POSITION, VELOCITY], 0.001))
        before = settings_of(runner, session, AXIS, 3)
        recorder = Recorder()
        source = PdoScopeSource(session, plan, confirmed_ctx(plan))
        runner.run(source.start(recorder.frames.append, recorder.events.append))
        axis.run(confirmed_call(motion.move, session, axis.node, 720, confirm=AXIS, ctx=SERVICE))
        axis.until(lambda status: status.status_bits[10].set and axis.read("0x6064") == 720, "at 720 °")
        axis.run(asyncio.sleep(0.2))
        texts = runner.run(source.stop())
    wire_frames = frames_in_bus_order(wire)
    on_bus = _wire_samples(wire_frames)

    assert [frame.sample for frame in recorder.frames] == list(range(len(recorder.frames)))
    assert len(recorder.frames) == sum(1 for m in wire_frames if m.arbitration_id == 0x080)
    got = [(frame.sample, frame.raw) for frame in recorder.frames if frame.raw != (None, None)]
    want = [(int.from_bytes(data[:4], "little", signed=True), int.from_bytes(data[4:8], "little", signed=True))
            for _n, data in on_bus]
    # every delivered sample is a TPDO frame of the bus, in bus order, with its values; a frame not delivered is
    # counted (late: after its sample went out, also after Stop; extra: a second one for a SYNC): that happens only on
    # a loaded machine, where the simulated drive was behind when node 7's first frame came (its samples start late:
    # the surplus frames at the end are counted; a bus thread behind no longer does that: the frame's bus timestamp
    # says its SYNC) or the bus thread stalls for longer than a sample waits (pdo_source.WAIT_S)
    assert len(got) + source.late + source.extra == len(want)
    samples = [sample for sample, _raw in got]
    assert samples == sorted(set(samples)), "one sample per SYNC, in order"
    if source.late + source.extra:  # a stall: what was delivered is still the bus's frames, in order
        at = 0
        for _sample, raw in got:
            while want[at] != raw:
                at += 1  # IndexError: a sample that is no TPDO frame of the bus
            at += 1
    else:
        assert [raw for _n, raw in got] == want, "every TPDO frame of the bus is a sample, with its values"
        # each frame answers one SYNC, in order: consecutive numbers, none after the SYNC the bus shows before it
        assert samples == list(range(samples[0], samples[0] + len(samples)))
        assert all(sample <= bus_n for sample, (bus_n, _d) in zip(samples, on_bus, strict=True))
    assert len(got) > 0.5 * len(recorder.frames)
    positions = [raw[0] for _n, raw in got]
    assert min(positions) < max(positions) and max(raw[1] for _n, raw in got) > 0  # it moved
    assert source.period_s > 0.0009
    assert any("mean period" in text for text in texts), texts
    assert any("restored and read back as before" in text for text in texts), texts
    assert settings_of(runner, session, AXIS, 3) == before
    assert wait_until(lambda: plant.nodes[AXIS].state.name == "PRE_OPERATIONAL")


class _StalledBusThread(can.Listener):
    """A loaded machine's bus thread: once armed, the session's frame thread stops at the next TPDO frame of node 7
    (ahead of the source's listener) until stop has delivered every sample of the recording, as a thread without
    the CPU would; the frames after it wait in the bus's queue."""

    def __init__(self, source: PdoScopeSource) -> None:
        self.source = source
        self.armed = threading.Event()
        self.held = 0

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == TPDO3 and self.armed.is_set():
            self.armed.clear()
            self.held += 1
            wait_until(lambda: self.source.delivered > self.source.newest_sync(), 60)


def test_an_answer_to_the_last_syncs_that_comes_after_stop_delivered_its_sample_is_counted_not_lost(
        plant_session: tuple[asyncio.Runner, Session], wire: can.BusABC, db: str) -> None:
    """A clean-clone run on a loaded machine lost one TPDO frame: stop took the source's listener off the bus once
    the count of answers looked complete (or after WAIT_S), and the node's answer to the last SYNC came after that.
    The listener now stays until the restore has answered (the node answers its SYNCs before the SDO requests
    after them): such a frame is counted as late."""
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION], 0.005))
    recorder = Recorder()
    source = PdoScopeSource(session, plan, confirmed_ctx(plan))
    stall = _StalledBusThread(source)
    frames_of(session.network).add_listener(stall)
    try:
        runner.run(source.start(recorder.frames.append, recorder.events.append))
        assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or any(
            frame.raw[0] is not None for frame in recorder.frames), 10), "node 7 answers"
        stall.armed.set()
        assert wait_until(lambda: stall.held == 1, 10), "a TPDO frame waits in the bus thread"
        runner.run(source.stop())  # more SYNCs went out meanwhile: their answers wait behind it
    finally:
        frames_of(session.network).remove_listener(stall)
    wire_frames = frames_in_bus_order(wire)
    on_bus = _wire_samples(wire_frames)
    got = [frame.raw[0] for frame in recorder.frames if frame.raw[0] is not None]
    assert len(recorder.frames) == sum(1 for m in wire_frames if m.arbitration_id == 0x080)
    assert len(got) + source.late + source.extra == len(on_bus), "every TPDO frame is a sample or counted"
    assert source.late >= 1, "the frames held in the bus thread came after their samples went out"


class _BehindAtAFirstFrame(can.Listener):
    """A loaded machine's bus thread, ahead of the source's listener: it stops at the first frame of the second node
    to answer (the other node's answers passed already, so the samples wait for them) until the producer has sent
    :data:`BEHIND` more SYNCs; the frames after it wait in the bus's queue, as for a thread without the CPU."""

    BEHIND = 5

    def __init__(self, source: PdoScopeSource, cobs: set[int]) -> None:
        self.source = source
        self.cobs = cobs
        self.seen: set[int] = set()
        self.held_at: int | None = None
        self.released = threading.Event()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id not in self.cobs or msg.arbitration_id in self.seen:
            return
        self.seen.add(msg.arbitration_id)
        if self.seen == self.cobs:
            held_at = self.held_at = self.source.newest_sync()
            wait_until(lambda: self.source.newest_sync() >= held_at + self.BEHIND, 60)
            self.released.set()


def _wire_answers(frames: list[can.Message], cob_id: int) -> list[tuple[int, bytes]]:
    """A TPDO's frames in bus order, each with the SYNC it answers by the bus: the newest SYNC before it on the
    wire, or one after the frame before when a device fell behind (two of its answers after one SYNC)."""
    count, found = -1, []
    for msg in frames:
        if msg.arbitration_id == 0x080:
            count += 1
        elif msg.arbitration_id == cob_id and count >= 0:
            number = count if not found else min(found[-1][0] + 1, count)
            if found and number == found[-1][0]:  # two answers after one SYNC: the run before it came late
                _one_back(found)
            found.append((number, bytes(msg.data)))
    return found


def _one_back(found: list[tuple[int, bytes]]) -> None:
    """Put the run of consecutive answers at the end of ``found`` one SYNC earlier where there is room (a device
    answers each SYNC once: its first answer came after the next SYNC was already on the bus)."""
    first = len(found) - 1
    while first > 0 and found[first - 1][0] == found[first][0] - 1:
        first -= 1
    if found[first][0] - 1 < (found[first - 1][0] + 1 if first else 0):
        return
    found[first:] = [(number - 1, data) for number, data in found[first:]]


def test_a_bus_thread_behind_at_a_nodes_first_frames_puts_them_at_the_sync_the_bus_shows(
        plant_session: tuple[asyncio.Runner, Session], wire: can.BusABC, db: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A loaded run took a node's first TPDO frame as the answer to the newest SYNC when the bus thread received
    it: behind by a few SYNCs, every later sample of that node was that many SYNCs late and the channels of two
    nodes did not line up. The bus's timestamp of the frame (the virtual bus stamps in time.time()'s clock) says
    which SYNC it answers."""
    monkeypatch.setattr(pdo_source, "WAIT_S", 60.0)  # the samples wait for the held frames however long the hold
    monkeypatch.setattr(pdo_source, "SILENT_S", 60.0)
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION, ScopeChannel(3, "0x6041")], 0.01))
    assert sorted(t.node for t in plan.tpdos) == [3, AXIS] and not plan.polling, plan.texts()
    slots = [slot for slot in plan.slots if slot is not None]
    recorder = Recorder()
    source = PdoScopeSource(session, plan, confirmed_ctx(plan))
    behind = _BehindAtAFirstFrame(source, {slot.cob_id for slot in slots})
    frames_of(session.network).add_listener(behind)
    try:
        runner.run(source.start(recorder.frames.append, recorder.events.append))
        assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or behind.released.is_set(), 60), "held, let go"
        held_at = behind.held_at
        assert held_at is not None
        assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or source.delivered > held_at + 20, 60)
        runner.run(source.stop())
    finally:
        frames_of(session.network).remove_listener(behind)
    wire_frames = frames_in_bus_order(wire)

    assert len(recorder.frames) == sum(1 for m in wire_frames if m.arbitration_id == 0x080)
    for at, slot in enumerate(plan.slots):
        assert slot is not None
        got = [(frame.sample, frame.raw[at]) for frame in recorder.frames if frame.raw[at] is not None]
        want = [(number, slot.value(data)) for number, data in _wire_answers(wire_frames, slot.cob_id)]
        assert got == want, f"TPDO 0x{slot.cob_id:03X}: each sample at the SYNC the bus shows before its frame"
    assert (source.late, source.extra) == (0, 0), "every TPDO frame of the bus is a sample"
    both = [frame.sample for frame in recorder.frames if None not in frame.raw]
    assert both and min(both) <= held_at, "the two nodes line up from the held frames on"


def test_a_node_that_stops_sending_is_an_event_in_words(
        plant_session: tuple[asyncio.Runner, Session], plant: Plant, db: str) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION, ScopeChannel(3, "0x6041")], 0.005))
    recorder = Recorder()
    source = PdoScopeSource(session, plan, confirmed_ctx(plan))
    runner.run(source.start(recorder.frames.append, recorder.events.append))
    assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or any(
        f.raw[1] is not None for f in recorder.frames), 10)
    plant.nodes[3].power_off()
    assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or any(
        e.node == 3 and "stopped sending" in e.text for e in recorder.events), 10), recorder.events
    plant.nodes[3].power_on()
    runner.run(source.stop())
    late = [f for f in recorder.frames[-20:]]
    assert all(f.raw[0] is not None for f in late[:5])  # node 7 went on


def test_the_recording_holds_the_node_lease_shared_with_the_same_writer(
        plant_session: tuple[asyncio.Runner, Session], db: str) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION], 0.005))
    anna = as_writer(Writer("anna", "panel:anna", "Scope"))
    needed = pdo_source.confirmation(plan)
    assert needed is not None
    source = PdoScopeSource(session, plan, anna.confirming(Confirmation(needed[0], needed[2])))
    runner.run(source.start(print, print))
    try:
        with pytest.raises(NodeLeased, match="anna"):
            runner.run(parameters.write(session, AXIS, "0x6065", 500, ctx=as_writer(Writer("ben", "panel:ben"))))
        runner.run(parameters.write(session, AXIS, "0x6065", 500, ctx=anna))  # her own tuning write
    finally:
        runner.run(source.stop())
    lease = node_lease.leases(session).current(AXIS)
    assert lease is not None and lease.active == 0  # the recording ended: it lapses as after anna's own writes


def test_a_tpdo_remapped_by_someone_else_meanwhile_is_not_overwritten(
        plant_session: tuple[asyncio.Runner, Session], plant: Plant, db: str) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION, VELOCITY], 0.005))
    source = PdoScopeSource(session, plan, confirmed_ctx(plan))
    runner.run(source.start(print, print))
    store = plant.nodes[AXIS].store  # another master on the bus maps the torque into TPDO3
    for sub, value in ((0, 0), (2, 0x6077_0010), (0, 2)):
        store.set(0x1A02, sub, value)
    texts = runner.run(source.stop())
    assert any("TPDO3 was remapped by someone else" in text and "left as it is" in text for text in texts), texts
    assert any("restore record is kept" in text for text in texts)
    assert store.get(0x1A02, 2) == 0x6077_0010
    assert len(restore_record.leftovers(db)) == 1


@pytest.fixture
def tripping_axis(registry: ProfileRegistry) -> Iterator[tuple[asyncio.Runner, Session, Plant]]:
    """The demo plant whose servo (node 7) trips on overcurrent above 250 ‰ of rated current."""
    plant_file = PlantFile.load(DEMO_PLANT)
    for node in plant_file.nodes:
        if node.node_id == AXIS:
            node.trip_current_permille = 250
    plant = Plant(plant_file, registry.get, bus=f"virtual:{fresh_channel()}@500000", latency="0ms").start()
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    session = runner.run(manager.open(plant.spec, "trip"))
    for node in plant.nodes.values():
        session.add_node(node.node_id, node.profile.id)
    yield runner, session, plant
    runner.run(manager.close_all())
    runner.close()
    plant.stop()


def test_the_current_spike_of_an_acceleration_and_the_overcurrent_trip_it_causes_are_recorded(
        tripping_axis: tuple[asyncio.Runner, Session, Plant], db: str) -> None:
    runner, session, plant = tripping_axis
    with Axis(runner, session, plant).kept_alive() as axis:  # a loaded run's steps outlast the guard's 2 s
        axis.enable()
        plan = runner.run(plan_recording(session, [ScopeChannel(AXIS, "0x6078"), ScopeChannel(AXIS, "0x6041", bit=3)],
                                         0.002))
        recorder = Recorder()
        source = PdoScopeSource(session, plan, confirmed_ctx(plan))
        runner.run(source.start(recorder.frames.append, recorder.events.append))
        with contextlib.suppress(Conflict):  # it may trip before it acknowledges the set-point
            axis.run(confirmed_call(motion.move, session, axis.node, 720, confirm=AXIS, ctx=SERVICE))
        axis.until(lambda status: status.state == "fault", "the overcurrent trip")
        axis.run(asyncio.sleep(0.2))
        runner.run(source.stop())
    values = [frame.raw for frame in recorder.frames if None not in frame.raw]
    spike = next(n for n, (current, _fault) in enumerate(values) if current is not None and abs(current) > 250)
    tripped = next(n for n, (_current, fault) in enumerate(values) if fault == 1)
    assert spike <= tripped, "the spike comes first, the fault bit (status word bit 3) after it"
    assert all(fault == 0 for _current, fault in values[:spike])
    assert plant.nodes[AXIS].drive.fault_code == 0x2310  # type: ignore[union-attr]


def test_another_sync_producer_on_the_bus_is_an_event_in_words(
        plant_session: tuple[asyncio.Runner, Session], wire: can.BusABC, db: str) -> None:
    runner, session = plant_session
    plan = runner.run(plan_recording(session, [POSITION], 0.005))
    recorder = Recorder()
    source = PdoScopeSource(session, plan, confirmed_ctx(plan))
    runner.run(source.start(recorder.frames.append, recorder.events.append))
    try:
        wire.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))  # a PLC produces SYNC too
        assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or any(
            "Another device sends SYNC" in event.text for event in recorder.events), 10), recorder.events
    finally:
        runner.run(source.stop())
