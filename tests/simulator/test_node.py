"""Simulated drives as CANopen slaves on a real python-can virtual bus, driven by canopen's SDO client.

SDO (expedited, segmented, block) and its abort codes, NMT and boot-up, heartbeat, EMCY, PDOs, the
processing-time latency, save/restore and Lenze device commands, and the Lenze second SDO channel.
Node 5 is a Lenze 8400 motec, node 12 a Lenze 8200 vector + EMF2178IB (both from their shipped profiles);
node 20 uses a test-only profile (the 8400 motec plus a long DOMAIN, a string, a range-limited and a
write-only object, and CiA 301 store/restore objects).
"""

from __future__ import annotations

import itertools
import statistics
import time
from collections.abc import Callable, Iterator
from typing import Any

import can
import canopen
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Access, ObjectEntry, Profile
from drivebench.protocol.canopen.nmt import NmtState
from drivebench.protocol.datatypes import DataType
from drivebench.simulator.lenze_control import INIT, WordControl
from drivebench.simulator.node import LOAD_SIGNATURE, SAVE_SIGNATURE, SDO_IDLE_S, Latency, SimulatedNode
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.conftest import wait_for_value
from tests.simulator.canopen_master import abort_code, remote

LENZE_8400, LENZE_8200, TEST_NODE = 5, 12, 20
LONG_DOMAIN = bytes(range(256)) * 4 + b"end"  # 1027 bytes: several block-transfer sub-blocks of 127 segments
C00324_1 = (0x5FFF - 324, 1)  # 8400 "CAN Tx inhibit time", U16 0..6500 ms


def wait_for(check: Callable[[], Any], timeout_s: float = 5.0, what: str = "condition") -> Any:
    return wait_for_value(check, timeout_s, what)


class Recorder(can.Listener):
    """Every frame on the wire, as (cob_id, data, timestamp)."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, bytes, float]] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append((msg.arbitration_id, bytes(msg.data), msg.timestamp))

    def clear(self) -> None:
        self.frames = []

    def of(self, cob_id: int) -> list[bytes]:
        return [data for cob, data, _ in list(self.frames) if cob == cob_id]

    def times(self, cob_id: int) -> list[float]:
        return [stamp for cob, _, stamp in list(self.frames) if cob == cob_id]


def extended_profile(base: Profile) -> Profile:
    """The 8400 motec profile plus objects no shipped profile has: long DOMAIN, WO, store/restore."""
    extra = [
        ObjectEntry(index=0x2000, name="Long domain", data_type=DataType.DOMAIN, default=LONG_DOMAIN.hex()),
        ObjectEntry(index=0x2001, name="Drive label", data_type=DataType.VISIBLE_STRING, default="conveyor"),
        ObjectEntry(index=0x2002, name="Password", data_type=DataType.UNSIGNED32, access=Access.WO),
        ObjectEntry(index=0x2003, name="Ramp", data_type=DataType.UNSIGNED16, min=2, max=10, default=5),
        *[ObjectEntry(index=0x1010, subindex=sub, name="Store parameters", data_type=DataType.UNSIGNED32,
                      default=1) for sub in (1, 2, 3)],
        *[ObjectEntry(index=0x1011, subindex=sub, name="Restore default parameters",
                      data_type=DataType.UNSIGNED32, default=1) for sub in (1, 2, 3)],
    ]
    return base.model_copy(update={"id": "test-8400-plus", "objects": [*base.objects, *extra]})


@pytest.fixture
def recorder(channel: str) -> Iterator[Recorder]:
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    listener = Recorder()
    notifier = can.Notifier(bus, [listener], timeout=0.05)
    yield listener
    notifier.stop()
    bus.shutdown()


@pytest.fixture
def plant(registry: ProfileRegistry, channel: str, recorder: Recorder) -> Iterator[Plant]:
    """Two Lenze drives with a 100 ms heartbeat and the test node (no heartbeat), without latency."""
    plant_file = PlantFile(name="node tests", bus=f"virtual:{channel}@500000", nodes=[
        PlantNode(node_id=LENZE_8400, profile="lenze-8400-motec-canopen", heartbeat_ms=100),
        PlantNode(node_id=LENZE_8200, profile="lenze-8200-vector-emf2178ib", heartbeat_ms=100)])
    running = Plant(plant_file, registry.get).start()
    running.add_node(extended_profile(registry.get("lenze-8400-motec-canopen")), TEST_NODE)
    yield running
    running.stop()


# --- SDO transfers ---------------------------------------------------------------------------------------
def test_expedited_download_and_upload(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, LENZE_8400)
    node.sdo.download(*C00324_1, (250).to_bytes(2, "little"))
    assert node.sdo.upload(*C00324_1) == (250).to_bytes(2, "little")
    assert plant.nodes[LENZE_8400].store.get(*C00324_1) == 250


def test_segmented_upload_and_download_of_a_string(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, TEST_NODE)
    assert node.sdo.upload(0x2001, 0) == b"conveyor"
    node.sdo.download(0x2001, 0, b"Conveyor belt 3, hall B")
    assert plant.nodes[TEST_NODE].store.get(0x2001, 0) == "Conveyor belt 3, hall B"
    assert node.sdo.upload(0x2001, 0) == b"Conveyor belt 3, hall B"


def test_segmented_upload_of_a_long_domain(master: canopen.Network) -> None:
    assert remote(master, TEST_NODE).sdo.upload(0x2000, 0) == LONG_DOMAIN


def test_block_upload_of_a_long_domain(master: canopen.Network, recorder: Recorder) -> None:
    node = remote(master, TEST_NODE)
    recorder.clear()
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as stream:
        assert stream.read() == LONG_DOMAIN
    initiate = wait_for(lambda: recorder.of(0x580 + TEST_NODE))
    assert isinstance(initiate, list)
    assert initiate[0][0] == 0xC6 and int.from_bytes(initiate[0][4:8], "little") == len(LONG_DOMAIN)


def test_block_download_of_a_long_domain(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, TEST_NODE)
    payload = bytes(reversed(LONG_DOMAIN))
    with node.sdo.open(0x2000, 0, "wb", size=len(payload), block_transfer=True) as stream:
        stream.write(payload)
    assert plant.nodes[TEST_NODE].store.get(0x2000, 0) == payload
    with node.sdo.open(0x2000, 0, "rb", block_transfer=True) as stream:
        assert stream.read() == payload


@pytest.mark.parametrize("size", [0, 1, 7, 8, 889, 890])  # 889 = one full sub-block of 127 segments
def test_block_download_sizes_at_the_edges(size: int, master: canopen.Network, plant: Plant) -> None:
    node = remote(master, TEST_NODE)
    payload = bytes((i * 7 + size) % 256 for i in range(size))
    with node.sdo.open(0x2000, 0, "wb", size=size, block_transfer=True) as stream:
        stream.write(payload)
    assert plant.nodes[TEST_NODE].store.get(0x2000, 0) == payload
    assert node.sdo.upload(0x2000, 0) == payload


def test_a_client_held_up_between_two_sub_blocks_keeps_its_transfer(master: canopen.Network, plant: Plant) -> None:
    """A program download's client held up 1.5 s after a sub-block's acknowledgement (a loaded host): the device
    waits for the next sub-block (the simulator dropped the transfer after 1 s and read the rest as new requests)."""
    node = remote(master, TEST_NODE)
    payload = bytes((i * 13) % 256 for i in range(3 * 889))
    with node.sdo.open(0x2000, 0, "wb", size=len(payload), block_transfer=True) as stream:
        stream.write(payload[:889])  # one full sub-block of 127 segments: the device acknowledges it
        time.sleep(1.5)
        stream.write(payload[889:])
    assert plant.nodes[TEST_NODE].store.get(0x2000, 0) == payload


def test_a_vanished_client_does_not_block_the_channel(master: canopen.Network, recorder: Recorder) -> None:
    """A block download left in its sub-block phase (every frame would be a segment) times out after SDO_IDLE_S."""
    master.send_message(0x600 + TEST_NODE, bytes.fromhex("C6 00 20 00 64 00 00 00"))  # then silence
    wait_for(lambda: recorder.of(0x580 + TEST_NODE))
    time.sleep(SDO_IDLE_S + 0.2)
    assert remote(master, TEST_NODE).sdo.upload(0x1018, 1) == (0x3B).to_bytes(4, "little")


def test_block_upload_of_the_8400_firmware_version(master: canopen.Network) -> None:
    """C00099 (0x5F9C), 11 characters: the manual's segmented example, here by block transfer."""
    with remote(master, LENZE_8400).sdo.open(0x5F9C, 0, "rb", block_transfer=True) as stream:
        assert stream.read() == b"01.00.00.00"


def test_8200_has_no_block_transfer(master: canopen.Network) -> None:
    """The EMF2178IB supports expedited and segmented SDO only: a block request is an unknown command."""
    node = remote(master, LENZE_8200)

    def block_read() -> bytes:
        with node.sdo.open(0x5F37, 0, "rb", block_transfer=True) as stream:
            return bytes(stream.read())

    assert abort_code(block_read) == 0x05040001
    assert node.sdo.upload(0x5F37, 0) == b"82S8212V_14000"  # the segmented path still works


# --- SDO abort codes ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(("node_id", "index", "sub", "code"), [
    pytest.param(LENZE_8400, 0x2FFF, 0, 0x06020000, id="unknown-object"),
    pytest.param(LENZE_8400, 0x1018, 9, 0x06090011, id="unknown-subindex"),
    pytest.param(TEST_NODE, 0x2002, 0, 0x06010001, id="read-of-write-only"),
])
def test_upload_aborts(node_id: int, index: int, sub: int, code: int, master: canopen.Network) -> None:
    assert abort_code(lambda: remote(master, node_id).sdo.upload(index, sub)) == code


@pytest.mark.parametrize(("node_id", "index", "sub", "data", "code"), [
    pytest.param(LENZE_8400, 0x2FFF, 0, b"\x01", 0x06020000, id="unknown-object"),
    pytest.param(LENZE_8400, 0x1018, 9, b"\x01", 0x06090011, id="unknown-subindex"),
    pytest.param(LENZE_8400, 0x1018, 1, (59).to_bytes(4, "little"), 0x06010002, id="read-only"),
    pytest.param(LENZE_8400, *C00324_1, (7000).to_bytes(2, "little"), 0x06090030, id="above-max"),
    pytest.param(TEST_NODE, 0x2003, 0, (20).to_bytes(2, "little"), 0x06090030, id="above-max-2..10"),
    pytest.param(TEST_NODE, 0x2003, 0, (1).to_bytes(2, "little"), 0x06090030, id="below-min-2..10"),
    # CiA 301 allows the general 0x06070010 or the specific "too high"/"too low"; like CANopenNode the
    # simulator answers the specific ones.
    pytest.param(LENZE_8400, 0x1017, 0, b"\x01\x02\x03", 0x06070012, id="length-too-high"),
    pytest.param(LENZE_8400, 0x1016, 1, b"\x01", 0x06070013, id="length-too-low"),
])
def test_download_aborts(node_id: int, index: int, sub: int, data: bytes, code: int,
                         master: canopen.Network, plant: Plant) -> None:
    store = plant.nodes[node_id].store
    before = store.get(index, sub) if store.has(index, sub) else None
    assert abort_code(lambda: remote(master, node_id).sdo.download(index, sub, data)) == code
    if before is not None:
        assert store.get(index, sub) == before


def test_a_refused_write_names_the_object_in_the_abort_frame(master: canopen.Network, recorder: Recorder) -> None:
    node = remote(master, LENZE_8400)
    recorder.clear()
    abort_code(lambda: node.sdo.download(0x1018, 1, bytes(4)))
    frame = wait_for(lambda: recorder.of(0x580 + LENZE_8400))
    assert isinstance(frame, list)
    assert frame[0] == bytes.fromhex("80 18 10 01 02 00 01 06")


# --- NMT, boot-up, heartbeat ---------------------------------------------------------------------------
@pytest.mark.parametrize("command", [0x81, 0x82], ids=["reset-node", "reset-communication"])
def test_reset_sends_boot_up_then_pre_operational_heartbeats(command: int, master: canopen.Network, plant: Plant,
                                                             recorder: Recorder) -> None:
    drive = plant.nodes[LENZE_8400]
    master.send_message(0x000, bytes([0x01, LENZE_8400]))
    wait_for(lambda: drive.state is NmtState.OPERATIONAL)
    wait_for(lambda: bytes([0x05]) in recorder.of(0x705))
    recorder.clear()
    master.send_message(0x000, bytes([command, LENZE_8400]))
    # An operational heartbeat the node sent before it took the reset may still come in first (a loaded machine).
    frames = wait_for(lambda: (f := recorder.of(0x705)) and b"\x00" in f and len(f) - f.index(b"\x00") >= 3 and f)
    assert isinstance(frames, list)
    before, after = frames[:frames.index(b"\x00")], frames[frames.index(b"\x00"):]
    assert set(before) <= {b"\x05"} and len(before) <= 1, f"before the boot-up: {before}"
    assert after[0] == b"\x00", "the first telegram of the reset node is the boot-up"
    assert all(frame == b"\x7f" for frame in after[1:3]), frames
    assert drive.state is NmtState.PRE_OPERATIONAL
    assert b"\x00" not in recorder.of(0x70C), "only node 5 was reset"


def test_broadcast_reset_boots_every_node(master: canopen.Network, recorder: Recorder) -> None:
    recorder.clear()
    master.send_message(0x000, bytes([0x81, 0]))
    for node_id in (LENZE_8400, LENZE_8200, TEST_NODE):
        wait_for(lambda node_id=node_id: b"\x00" in recorder.of(0x700 + node_id))  # type: ignore[misc]


def test_nmt_start_stop_pre_operational_follow_in_the_heartbeat(master: canopen.Network,
                                                                recorder: Recorder) -> None:
    for command, state in [(0x01, 0x05), (0x02, 0x04), (0x80, 0x7F)]:
        master.send_message(0x000, bytes([command, LENZE_8200]))
        wait_for(lambda state=state: recorder.of(0x70C)[-1:] == [bytes([state])])  # type: ignore[misc]


def test_reset_node_restores_saved_values_and_reset_communication_keeps_application_values(
        master: canopen.Network, plant: Plant) -> None:
    node, store = remote(master, LENZE_8400), plant.nodes[LENZE_8400].store
    node.sdo.download(*C00324_1, (250).to_bytes(2, "little"))
    node.sdo.download(0x1017, 0, (300).to_bytes(2, "little"))
    master.send_message(0x000, bytes([0x82, LENZE_8400]))
    wait_for(lambda: store.get(0x1017, 0) == 100)  # communication object back to its saved value
    assert store.get(*C00324_1) == 250  # an application value survives reset communication
    master.send_message(0x000, bytes([0x81, LENZE_8400]))
    wait_for(lambda: store.get(*C00324_1) == 0)


def _median_interval(stamps: list[float]) -> float:
    return statistics.median(b - a for a, b in itertools.pairwise(stamps))


def test_heartbeat_period_follows_writes_to_0x1017(master: canopen.Network, recorder: Recorder) -> None:
    """Compares periods measured from frame timestamps with each other, not with the wall clock."""
    node = remote(master, TEST_NODE)
    node.sdo.download(0x1017, 0, (20).to_bytes(2, "little"))
    wait_for(lambda: len(recorder.times(0x700 + TEST_NODE)) >= 12)
    fast = _median_interval(recorder.times(0x700 + TEST_NODE)[-10:])
    node.sdo.download(0x1017, 0, (200).to_bytes(2, "little"))
    recorder.clear()
    wait_for(lambda: len(recorder.times(0x700 + TEST_NODE)) >= 4)
    slow = _median_interval(recorder.times(0x700 + TEST_NODE))
    assert slow > 3 * fast, (fast, slow)
    node.sdo.download(0x1017, 0, (0).to_bytes(2, "little"))
    time.sleep(0.05)
    recorder.clear()
    time.sleep(0.5)
    assert recorder.of(0x700 + TEST_NODE) == [], "0x1017 = 0 switches the heartbeat off"


# --- EMCY ----------------------------------------------------------------------------------------------
def test_emcy_raise_and_clear(master: canopen.Network, plant: Plant, recorder: Recorder) -> None:
    drive, node = plant.nodes[LENZE_8400], remote(master, LENZE_8400)
    recorder.clear()
    drive.raise_emcy(0x2310, 0x03, b"\x01\x02")
    frame = wait_for(lambda: recorder.of(0x85))
    assert isinstance(frame, list)
    assert frame[0] == bytes.fromhex("10 23 03 01 02 00 00 00")
    assert node.sdo.upload(0x1001, 0) == b"\x03"
    assert node.sdo.upload(0x1003, 0) == b"\x01"
    assert int.from_bytes(node.sdo.upload(0x1003, 1), "little") == 0x0201_2310
    drive.raise_emcy(0x4210, 0x09)
    assert node.sdo.upload(0x1003, 0) == b"\x02"
    assert int.from_bytes(node.sdo.upload(0x1003, 1), "little") == 0x4210, "the newest error is sub 1"
    assert int.from_bytes(node.sdo.upload(0x1003, 2), "little") == 0x0201_2310
    drive.clear_emcy()
    wait_for(lambda: recorder.of(0x85)[-1:] == [bytes(8)])
    assert node.sdo.upload(0x1001, 0) == b"\x00"


def test_writing_0_to_0x1003_deletes_the_error_history(master: canopen.Network, plant: Plant) -> None:
    drive, node = plant.nodes[LENZE_8400], remote(master, LENZE_8400)
    drive.raise_emcy(0x2310, 0x03)
    drive.raise_emcy(0x4210, 0x09)
    assert abort_code(lambda: node.sdo.download(0x1003, 0, b"\x05")) == 0x06090030
    assert node.sdo.upload(0x1003, 0) == b"\x02", "a refused write changes nothing"
    node.sdo.download(0x1003, 0, b"\x00")
    assert node.sdo.upload(0x1003, 0) == b"\x00"
    assert node.sdo.upload(0x1003, 1) == bytes(4)


def test_emcy_uses_the_cob_id_of_0x1014(master: canopen.Network, plant: Plant, recorder: Recorder) -> None:
    node = remote(master, LENZE_8400)
    node.sdo.download(0x1014, 0, (0x0A5).to_bytes(4, "little"))
    plant.nodes[LENZE_8400].raise_emcy(0x1000)
    wait_for(lambda: recorder.of(0x0A5))
    node.sdo.download(0x1014, 0, (0x800000A5).to_bytes(4, "little"))
    recorder.clear()
    plant.nodes[LENZE_8400].raise_emcy(0x1000)
    time.sleep(0.2)
    assert recorder.of(0x0A5) == [] and recorder.of(0x85) == [], "bit 31 set: EMCY not sent"


# --- PDO -----------------------------------------------------------------------------------------------
def test_event_tpdo_is_sent_per_its_mapping_only_when_operational(master: canopen.Network, plant: Plant,
                                                                  recorder: Recorder) -> None:
    """8200 TPDO1 maps AIF-OUT words 1..3 (0x58E0 sub 1..3, 16 bit each), transmission type 254."""
    drive = plant.nodes[LENZE_8200]
    # AIF-OUT word 1 is also the status word: wait until the drive has left its start-up state and published it
    # (a test that wrote first lost its value to that publication on a loaded machine)
    wait_for(lambda: isinstance(drive.drive, WordControl) and drive.drive.device_state != INIT
             and drive.store.get(0x58E0, 1) != 0)
    drive.store.set(0x58E0, 1, 0x1234)
    drive.store.set(0x58E0, 3, -2)
    time.sleep(0.1)
    assert recorder.of(0x18C) == [], "no PDO in pre-operational"
    master.send_message(0x000, bytes([0x01, LENZE_8200]))
    first = wait_for(lambda: recorder.of(0x18C))
    assert isinstance(first, list)
    assert first[0] == bytes.fromhex("34 12 00 00 FE FF")
    drive.store.set(0x58E0, 2, 7)  # on change
    wait_for(lambda: bytes.fromhex("34 12 07 00 FE FF") in recorder.of(0x18C))


def test_sync_tpdo_is_sent_every_nth_sync(master: canopen.Network, plant: Plant, recorder: Recorder) -> None:
    node = remote(master, LENZE_8200)
    node.sdo.download(0x1800, 2, b"\x02")  # every 2nd SYNC
    master.send_message(0x000, bytes([0x01, LENZE_8200]))
    wait_for(lambda: plant.nodes[LENZE_8200].state is NmtState.OPERATIONAL)
    time.sleep(0.1)
    recorder.clear()
    for _ in range(6):
        master.send_message(0x080, b"")
        time.sleep(0.02)
    wait_for(lambda: len(recorder.of(0x18C)) == 3)
    time.sleep(0.1)
    assert len(recorder.of(0x18C)) == 3


def test_rpdo_updates_the_mapped_objects(master: canopen.Network, plant: Plant) -> None:
    """8200 RPDO1 maps AIF-IN words 1..3 (0x58E1 sub 1..3)."""
    drive = plant.nodes[LENZE_8200]
    master.send_message(0x20C, bytes.fromhex("01 00 02 00 FF FF"))
    time.sleep(0.1)
    assert drive.store.get(0x58E1, 1) == 0, "RPDOs are ignored in pre-operational"
    master.send_message(0x000, bytes([0x01, LENZE_8200]))
    wait_for(lambda: drive.state is NmtState.OPERATIONAL)
    master.send_message(0x20C, bytes.fromhex("01 00 02 00 FF FF"))
    wait_for(lambda: drive.store.get(0x58E1, 3) == -1)
    assert (drive.store.get(0x58E1, 1), drive.store.get(0x58E1, 2)) == (1, 2)
    assert remote(master, LENZE_8200).sdo.upload(0x58E1, 2) == b"\x02\x00"


# --- latency --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "mean_ms", "jitter_ms"), [
    ("30ms±20ms", 30, 20), ("30ms+-20ms", 30, 20), ("30 ms ± 20 ms", 30, 20), ("5ms", 5, 0), ("0.5s", 500, 0),
    ("12", 12, 0), ("", 0, 0), ("250us", 0.25, 0),
])
def test_latency_parse(text: str, mean_ms: float, jitter_ms: float) -> None:
    latency = Latency.parse(text)
    assert latency.mean_s == pytest.approx(mean_ms / 1000)
    assert latency.jitter_s == pytest.approx(jitter_ms / 1000)


def test_latency_samples_stay_in_the_band() -> None:
    latency = Latency.parse("30ms±20ms")
    samples = [latency.sample() for _ in range(500)]
    assert min(samples) >= 0.010 and max(samples) <= 0.050
    assert str(latency) == "30 ms ± 20 ms"


def test_latency_delays_every_sdo_response(registry: ProfileRegistry, master: canopen.Network,
                                           plant: Plant) -> None:
    """With 30 ms ± 20 ms no answer may come sooner than 10 ms (a lower bound only: sleeps never end early)."""
    plant.add_node(registry.get("lenze-8400-motec-canopen"), 30, latency=Latency.parse("30ms±20ms"))
    node = remote(master, 30)
    for _ in range(5):
        started = time.perf_counter()
        node.sdo.upload(0x1018, 1)
        assert time.perf_counter() - started >= 0.010


# --- save, restore, device commands ---------------------------------------------------------------------
def test_save_and_restore_defaults_with_0x1010_and_0x1011(master: canopen.Network, plant: Plant) -> None:
    node, store = remote(master, TEST_NODE), plant.nodes[TEST_NODE].store
    node.sdo.download(0x2003, 0, (8).to_bytes(2, "little"))
    node.sdo.download(0x1010, 1, SAVE_SIGNATURE.to_bytes(4, "little"))
    node.sdo.download(0x2003, 0, (9).to_bytes(2, "little"))
    master.send_message(0x000, bytes([0x81, TEST_NODE]))
    wait_for(lambda: store.get(0x2003, 0) == 8)  # the saved value comes back after reset node
    node.sdo.download(0x1011, 1, LOAD_SIGNATURE.to_bytes(4, "little"))
    assert store.get(0x2003, 0) == 8, "restored defaults take effect at the next reset"
    master.send_message(0x000, bytes([0x81, TEST_NODE]))
    wait_for(lambda: store.get(0x2003, 0) == 5)


def test_store_without_the_save_signature_is_refused(master: canopen.Network) -> None:
    """CiA 301: only 'save' (0x65766173) stores, only 'load' (0x64616F6C) restores; else abort 0x08000020."""
    node = remote(master, TEST_NODE)
    assert abort_code(lambda: node.sdo.download(0x1010, 1, (1234).to_bytes(4, "little"))) == 0x08000020
    assert abort_code(lambda: node.sdo.download(0x1011, 1, (1234).to_bytes(4, "little"))) == 0x08000020


def test_lenze_c00002_11_saves_and_c00002_26_resets_the_node(master: canopen.Network, plant: Plant,
                                                            recorder: Recorder) -> None:
    """8400: C00002 = index 0x5FFD; subcode 11 'save all parameter sets', 26 'CAN reset node'."""
    node, store = remote(master, LENZE_8400), plant.nodes[LENZE_8400].store
    node.sdo.download(*C00324_1, (250).to_bytes(2, "little"))
    node.sdo.download(0x5FFD, 11, b"\x01")
    node.sdo.download(*C00324_1, (500).to_bytes(2, "little"))
    recorder.clear()
    node.sdo.download(0x5FFD, 26, b"\x01")
    wait_for(lambda: b"\x00" in recorder.of(0x705))
    wait_for(lambda: store.get(*C00324_1) == 250)


# --- the Lenze second SDO channel -------------------------------------------------------------------------
def test_sdo2_answers_on_its_own_cob_ids_once_valid(master: canopen.Network, plant: Plant) -> None:
    """8400 motec manual, I-1201 example (TV-8): rx 0x640 + id, tx 0x5C0 + id; invalid (bit 31) by default."""
    node = remote(master, LENZE_8400)
    sdo2 = node.add_sdo(0x645, 0x5C5)
    sdo2.network = master  # canopen 2.4.1 add_sdo() on an attached node leaves it unset
    sdo2.RESPONSE_TIMEOUT = 0.3
    sdo2.MAX_RETRIES = 1
    with pytest.raises(canopen.SdoCommunicationError):
        sdo2.upload(0x1018, 1)
    node.sdo.download(0x1201, 1, (0x645).to_bytes(4, "little"))
    node.sdo.download(0x1201, 2, (0x5C5).to_bytes(4, "little"))
    sdo2.RESPONSE_TIMEOUT = 2.0
    assert sdo2.upload(0x1018, 1) == (0x3B).to_bytes(4, "little")
    with sdo2.open(0x5F9C, 0, "rb") as stream:  # segmented on SDO2 too
        assert stream.read() == b"01.00.00.00"
    assert node.sdo.upload(0x1018, 1) == (0x3B).to_bytes(4, "little"), "SDO1 keeps working"


def test_8200_sdo2_is_deactivated_in_the_lenze_setting(plant: Plant) -> None:
    """EMF2178IB: SDO2 'Lenze setting: not active'; its COB-IDs are 0x640/0x5C0 + node id with bit 31 set."""
    drive: SimulatedNode = plant.nodes[LENZE_8200]
    assert drive.store.get(0x1201, 1) == 0x80000000 + 0x640 + LENZE_8200
    assert drive.store.get(0x1201, 2) == 0x80000000 + 0x5C0 + LENZE_8200
    assert list(drive.sdo_servers) == [0x600 + LENZE_8200]
