"""The parameter service against simulated drives on a real virtual CAN bus (no mocks of the protocol layer)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Coroutine, Iterator
from typing import Any, TypeVar

import can
import pytest

from drivebench.device.profiles.commands import CommandsSection, CommandWrite
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import (
    Conflict,
    InvalidValue,
    OutOfRange,
    ReadOnly,
    SdoAbortError,
    SdoTimeoutError,
    UnknownParameter,
    UnknownProfile,
)
from drivebench.protocol.datatypes import DataType
from drivebench.services.bus.sessions import Session
from drivebench.services.params import parameters
from drivebench.services.params.jobs import JobManager, JobState
from drivebench.services.params.parameters import DeviceCommand
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile
from tests.conftest import wait_until
from tests.write_contexts import SERVICE

T = TypeVar("T")
ABSENT = 40
PLANT = {
    "name": "Parameter test plant",
    "nodes": [
        {"node_id": 2, "profile": "lenze-8400-motec-canopen"},
        {"node_id": 3, "profile": "siemens-micromaster4-canopen"},
        {"node_id": 5, "profile": "lenze-8400-motec-canopen", "values": {"C00061": 43}},
        {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib"},
    ],
}


class Bench:
    """A session on a simulated plant, driven from one event loop."""

    def __init__(self, runner: asyncio.Runner, session: Session, plant: Plant, wire: can.BusABC) -> None:
        self.runner = runner
        self.session = session
        self.plant = plant
        self.wire = wire
        self.jobs = JobManager()

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self.runner.run(coro)

    def frames(self) -> list[can.Message]:
        found = []
        while (msg := self.wire.recv(timeout=0.05)) is not None:
            found.append(msg)
        return found


@contextlib.contextmanager
def open_bench(registry: ProfileRegistry, channel: str, absent_profile: str = "lenze-8400-motec-canopen"
               ) -> Iterator[Bench]:
    """The plant, the wire and the session, each closed (in reverse) from the moment it is open: a set-up that
    fails half-way leaves no plant running."""
    with contextlib.ExitStack() as opened:
        plant = Plant(PlantFile.model_validate(PLANT), registry.get, bus=f"virtual:{channel}@500000",
                      latency="0ms").start()
        opened.callback(plant.stop)
        wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        opened.callback(wire.shutdown)
        runner = opened.enter_context(asyncio.Runner())
        manager = SessionManager(registry, sdo_timeout_s=0.3, sdo_retries=0)
        opened.callback(lambda: runner.run(manager.close_all()))
        session = runner.run(manager.open(plant.spec, "params"))
        for node in PLANT["nodes"]:
            session.add_node(node["node_id"], node["profile"])  # type: ignore[arg-type]
        session.add_node(ABSENT, absent_profile)
        yield Bench(runner, session, plant, wire)


@pytest.fixture
def bench(registry: ProfileRegistry, channel: str) -> Iterator[Bench]:
    with open_bench(registry, channel) as opened:
        yield opened


def test_a_bench_whose_set_up_fails_leaves_no_plant_running(registry: ProfileRegistry, channel: str) -> None:
    before = set(threading.enumerate())
    with pytest.raises(UnknownProfile), open_bench(registry, channel, absent_profile="no-such-profile"):
        pass
    assert wait_until(lambda: not [t for t in threading.enumerate() if t not in before and t.is_alive()
                                   and t.name.startswith("sim-")], 15), "the plant's threads are still running"


# --- reads -------------------------------------------------------------------------------------------------
def test_read_c00061_on_the_8400_is_43_degrees(bench: Bench) -> None:
    bench.frames()
    value = bench.run(parameters.read(bench.session, 5, "C00061"))
    assert (value.raw, value.value, value.unit, value.display) == (43, 43, "°C", "43 °C")
    sent = [bytes(m.data) for m in bench.frames() if m.arbitration_id == 0x605]
    assert sent == [bytes.fromhex("40 C2 5F 00 00 00 00 00")]  # manual 9.3.1


def test_write_c00088_sends_raw_1020_and_reads_back(bench: Bench) -> None:
    bench.run(parameters.write(bench.session, 5, "C00088", "7.5", ctx=SERVICE))
    bench.frames()
    result = bench.run(parameters.write(bench.session, 5, "C00088", "10.20 A", ctx=SERVICE))
    assert result.written.raw == 1020 and result.verified is True and result.mismatch is None
    assert result.read_back is not None and result.read_back.display == "10.20 A"
    downloads = [bytes(m.data) for m in bench.frames() if m.arbitration_id == 0x605 and m.data[0] & 0xE0 == 0x20]
    assert downloads == [bytes.fromhex("23 A7 5F 00 FC 03 00 00")]  # manual 9.3.2
    assert bench.plant.nodes[5].store.get_ref("C00088") == 1020


def test_selection_text_of_c00351(bench: Bench) -> None:
    value = bench.run(parameters.read(bench.session, 5, "C00351"))
    assert (value.raw, value.text, value.display) == (0, "500 kbit/s", "0 = 500 kbit/s")


def test_string_c00099_by_segmented_and_by_block_upload(bench: Bench) -> None:
    bench.frames()
    assert bench.run(parameters.read(bench.session, 5, "C00099")).value == "01.00.00.00"
    commands = [m.data[0] for m in bench.frames() if m.arbitration_id == 0x585]
    assert commands[0] == 0x41  # segmented: initiate with size indicated
    assert bench.run(parameters.read(bench.session, 5, "C00099", transfer="block")).value == "01.00.00.00"
    commands = [m.data[0] for m in bench.frames() if m.arbitration_id == 0x585]
    assert commands[0] & 0xE0 == 0xC0  # block upload response


def test_bit_coded_word_shows_named_bits(bench: Bench) -> None:
    bench.plant.nodes[5].store.set_ref("C00349", 0b101)
    value = bench.run(parameters.read(bench.session, 5, "C00349"))
    bits = bench.session.node(5).catalog.resolve("C00349").entry.bits  # type: ignore[union-attr]
    assert value.text == ", ".join([bits[0], bits[2]]) and value.display == "0x0005"


def test_emf2178ib_fix32_values(bench: Bench) -> None:
    """EMF2178IB section 10.5: C0061 = 43 °C travels as 430000; C0012 = 20 s as 200000."""
    value = bench.run(parameters.read(bench.session, 12, "C0061"))
    assert (value.raw, value.value, value.display) == (430000, 43, "43 °C")
    result = bench.run(parameters.write(bench.session, 12, "C0012", 20, ctx=SERVICE))
    assert result.written.raw == 200000 and result.verified
    with pytest.raises(InvalidValue, match="decimals"):
        bench.run(parameters.write(bench.session, 12, "C0012", "1.00005", ctx=SERVICE))


def test_micromaster_p_parameters(bench: Bench) -> None:
    assert bench.run(parameters.read(bench.session, 3, "r0964.2")).raw == 105
    assert bench.run(parameters.write(bench.session, 3, "P1203", 99, ctx=SERVICE)).verified
    with pytest.raises(OutOfRange, match=r"P1203.*10 \.\.\. 200 %"):
        bench.run(parameters.write(bench.session, 3, "P1203", 300, ctx=SERVICE))
    assert bench.run(parameters.write(bench.session, 3, "P1082", "45.5 Hz",
                                      ctx=SERVICE)).read_back.value == 45.5  # type: ignore[union-attr]


def test_micromaster_indexed_parameters_as_siemens_writes_them(bench: Bench) -> None:
    """``r0964[2]`` is ``r0964.2``; an index the profile does not list goes to the device, which refuses it."""
    assert bench.run(parameters.read(bench.session, 3, "r0964[2]")).raw == 105
    assert bench.run(parameters.read(bench.session, 3, "P0700[0]")).display == "2 = Terminal"
    with pytest.raises(SdoAbortError) as caught:
        bench.run(parameters.read(bench.session, 3, "P0700[1]"))
    assert (caught.value.abort_code, caught.value.index, caught.value.subindex) == (0x06090011, 0x22BC, 1)
    with pytest.raises(OutOfRange, match="selection list"):  # the profile's checks still apply to the index
        bench.run(parameters.write(bench.session, 3, "P0700[1]", 9, ctx=SERVICE))
    assert [item.ref for item in parameters.items(bench.session.node(3), "P0700[1]")] == ["P0700.1"]


def test_search_finds_an_index_the_profile_does_not_list(bench: Bench) -> None:
    found = parameters.items(bench.session.node(5), "0x6040")
    assert [(item.index, item.subindex, item.name) for item in found] == [(0x6040, 0, "(not in the profile)")]
    assert parameters.items(bench.session.node(5), "no such words") == []


# --- validation before sending, and the device's aborts ---------------------------------------------------
def test_validation_happens_before_anything_is_sent(bench: Bench) -> None:
    bench.frames()
    with pytest.raises(OutOfRange, match=r"C00350 \(CAN node address\): 100 is outside the allowed range 1 \.\.\. 63"):
        bench.run(parameters.write(bench.session, 5, "C00350", 100, ctx=SERVICE))
    with pytest.raises(ReadOnly, match="C00061"):
        bench.run(parameters.write(bench.session, 5, "C00061", 3, ctx=SERVICE))
    with pytest.raises(OutOfRange, match="selection list"):
        bench.run(parameters.write(bench.session, 5, "C00351", 9, ctx=SERVICE))
    with pytest.raises(OutOfRange, match="UNSIGNED8"):
        bench.run(parameters.write(bench.session, 5, "C00351", 300, check=False, ctx=SERVICE))  # never truncated to 44
    with pytest.raises(InvalidValue, match="expects a number"):
        bench.run(parameters.write(bench.session, 5, "C00088", "ten", ctx=SERVICE))
    assert [m for m in bench.frames() if m.arbitration_id == 0x605] == []


@pytest.mark.parametrize(("ref", "value", "code"), [
    ("C00061", 3, 0x06010002),   # read-only
    ("C00350", 100, 0x06090030),  # range
])
def test_device_aborts_when_the_profile_check_is_skipped(bench: Bench, ref: str, value: int, code: int) -> None:
    with pytest.raises(SdoAbortError) as caught:
        bench.run(parameters.write(bench.session, 5, ref, value, check=False, ctx=SERVICE))
    assert caught.value.abort_code == code and caught.value.node == 5 and caught.value.abort_text


def test_unknown_object_aborts_and_unknown_code_is_refused(bench: Bench) -> None:
    with pytest.raises(SdoAbortError) as caught:
        bench.run(parameters.read(bench.session, 5, "0x2FFF.0"))
    assert caught.value.abort_code == 0x06020000
    with pytest.raises(UnknownParameter, match="C09999"):
        bench.run(parameters.read(bench.session, 5, "C09999"))


def test_absent_node_times_out_without_blocking_others(bench: Bench) -> None:
    """While the absent node's request waits for its timeout, reads of the other nodes complete."""
    parameters.configure(bench.session, parameters.SdoSettings(timeout_s=3.0, retries=0))

    async def go() -> tuple[int, bool]:
        silent = asyncio.ensure_future(parameters.read(bench.session, ABSENT, "C00061"))
        await asyncio.sleep(0)
        others = await asyncio.gather(*(parameters.read(bench.session, node, "0x1018.1")
                                        for node in (2, 3, 5, 12) for _ in range(3)))
        still_waiting = not silent.done()
        with pytest.raises(SdoTimeoutError) as caught:
            await silent
        assert caught.value.node == ABSENT
        return len(others), still_waiting

    count, still_waiting = bench.run(go())
    assert count == 12 and still_waiting



def test_repeated_reads_follow_the_device_value(bench: Bench) -> None:
    """Scaling is remembered per item for the last raw value: a changed value is scaled afresh."""
    store = bench.plant.nodes[5].store
    store.set_ref("C00088", 1020)
    first = bench.run(parameters.read(bench.session, 5, "C00088"))
    store.set_ref("C00088", 750)
    second = bench.run(parameters.read(bench.session, 5, "C00088"))
    again = bench.run(parameters.read(bench.session, 5, "88"))
    assert (first.raw, first.display) == (1020, "10.20 A")
    assert (second.raw, second.value, second.display) == (750, 7.5, "7.50 A")
    assert (again.ref, again.display) == ("C00088", "7.50 A")
    assert parameters.service(bench.session).values[5]["C00088"] is again


def test_a_retry_then_abort_of_an_unanswered_read(bench: Bench) -> None:
    """With one retry, the request goes out twice; then the tool aborts the transfer (CiA 301 0x05040000)."""
    parameters.configure(bench.session, parameters.SdoSettings(timeout_s=0.1, retries=1))
    bench.frames()
    with pytest.raises(SdoTimeoutError):
        bench.run(parameters.read(bench.session, ABSENT, "C00061"))
    sent = [bytes(m.data) for m in bench.frames() if m.arbitration_id == 0x600 + ABSENT]
    request = bytes.fromhex("40 C2 5F 00 00 00 00 00")
    assert sent == [request, request, bytes.fromhex("80 C2 5F 00 00 00 04 05")]


def test_a_cancelled_read_leaves_the_channel_usable(bench: Bench) -> None:
    parameters.configure(bench.session, parameters.SdoSettings(timeout_s=5.0, retries=0))

    async def go() -> tuple[bool, int | float | str | None]:
        waiting = asyncio.ensure_future(parameters.read(bench.session, ABSENT, "C00061"))
        await asyncio.sleep(0.05)
        waiting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiting
        lock_free = not bench.session.client(ABSENT).channels[0].lock.locked()
        other = await parameters.read(bench.session, 5, "C00061")
        return lock_free, other.value

    assert bench.run(go()) == (True, 43)


# --- reset-required, device commands ----------------------------------------------------------------------
def test_reset_required_flag_until_reset_node(bench: Bench) -> None:
    node = bench.session.node(5)
    result = bench.run(parameters.write(bench.session, 5, "C00351", "250 kbit/s", ctx=SERVICE))
    assert result.reset_required and node.pending_reset == {"C00351"}
    bench.run(parameters.command(bench.session, 5, DeviceCommand.SAVE, ctx=SERVICE))
    assert node.pending_reset == {"C00351"}
    bench.plant.nodes[5].on_frame(0x000, bytes([0x81, 5]), time.time())  # someone else resets the node
    assert wait_until(lambda: not node.pending_reset, 5)
    assert node.pending_reset == set()


def test_device_commands_per_profile(bench: Bench) -> None:
    saved = bench.run(parameters.command(bench.session, 5, DeviceCommand.SAVE, ctx=SERVICE))
    assert saved.via == "C00002/11 = 1"
    bench.run(parameters.write(bench.session, 12, "C0012", 30, ctx=SERVICE))
    assert bench.run(parameters.command(bench.session, 12, DeviceCommand.SAVE, ctx=SERVICE)).via == "0x1010.1 = 'save'"
    assert bench.plant.nodes[12].store.saved[(0x5FF3, 0)] == 300000
    restored = bench.run(parameters.command(bench.session, 3, DeviceCommand.RESTORE_DEFAULTS, ctx=SERVICE))
    assert restored.via == "0x1011.1 = 'load'"
    assert "restore defaults" in bench.session.node(3).pending_reset
    bench.run(parameters.command(bench.session, 3, DeviceCommand.RESET_NODE, ctx=SERVICE))
    assert bench.session.node(3).pending_reset == set()


def test_a_command_the_profile_names_but_does_not_list_is_refused_in_words(bench: Bench) -> None:
    node = bench.session.node(5)
    commands = CommandsSection(save=CommandWrite(ref="C09999", value=1, done="saved"))
    node.profile = node.profile.model_copy(update={"commands": commands}) if node.profile else None
    with pytest.raises(Conflict, match="save command writes C09999, which the profile does not list"):
        bench.run(parameters.command(bench.session, 5, DeviceCommand.SAVE, ctx=SERVICE))


# --- read-all jobs -----------------------------------------------------------------------------------------
def test_read_all_of_several_nodes_uses_sdo2(bench: Bench) -> None:
    async def go() -> Any:
        job = parameters.start_read(bench.session, [2, 5, 12], bench.jobs, ctx=SERVICE)
        await job.wait()
        return job

    job = bench.run(go())
    assert job.state is JobState.DONE and job.failed == 0
    assert job.done == job.total == sum(len(parameters.readable_items(bench.session.node(n))) for n in (2, 5, 12))
    assert job.result["values"]["5"]["C00061"].display == "43 °C"
    assert any("SDO2 activated on node 5 (0x645/0x5C5" in note for note in job.notes)
    assert bench.plant.nodes[5].store.get(0x1201, 1) == 0x645
    assert len(bench.session.network.nodes[5].channels) == 2
    assert any(m.arbitration_id == 0x645 for m in bench.frames())  # reads really went over SDO2


def test_a_batch_answer_only_canopens_client_reads_is_read_there_without_asking_the_loop_again(bench: Bench) -> None:
    """A profile that calls C00099 an UNSIGNED32 while the device answers it segmented: the batch aborts that answer
    (it asked for an expedited one) and the worker thread's client reads it next; one initiate on the loop, not two."""
    node = bench.session.node(5)
    assert node.profile is not None
    parameters_ = [p.model_copy(update={"data_type": DataType.UNSIGNED32}) if p.code == "C00099" else p
                   for p in node.profile.parameters]
    node.profile = node.profile.model_copy(update={"parameters": parameters_})
    bench.frames()
    (result,) = bench.run(parameters.read_many(bench.session, 5, ["C00099"]))
    assert not isinstance(result, Exception) and isinstance(result.raw, int)
    initiates = [m for m in bench.frames() if m.arbitration_id == 0x605 and m.data[:4] == bytes.fromhex("40 9C 5F 00")]
    assert len(initiates) == 2  # the batch's, then canopen's client's


def test_a_scan_after_sdo2_was_activated_lists_no_node_behind_it(bench: Bench) -> None:
    """Node 5's SDO2 (0x645/0x5C5) are node 69's default SDO identifiers: the scan does not ask 69, so node 5 does
    not answer as a phantom node 69 (found by a browser sweep: 'Node 69 · Unknown device' after a read-all)."""
    async def go() -> list[int]:
        job = parameters.start_read(bench.session, [5], bench.jobs, ctx=SERVICE)
        await job.wait()
        assert len(bench.session.network.nodes[5].channels) == 2
        return [node.node_id for node in await bench.session.scan(0.3)]

    found = bench.run(go())
    assert 5 in found and 69 not in found
    assert 69 not in bench.session.nodes


def test_read_all_with_a_silent_node_finishes_and_reports_it(bench: Bench) -> None:
    async def go() -> Any:
        job = parameters.start_read(bench.session, [ABSENT, 5], bench.jobs, ctx=SERVICE)
        await job.wait()
        return job

    job = bench.run(go())
    assert job.state is JobState.INCOMPLETE and job.done == job.total and job.not_done > 0  # issue 28 item 5
    assert len(job.result["values"]["5"]) == len(parameters.readable_items(bench.session.node(5)))
    assert job.result["values"][str(ABSENT)] == {}
    assert any(f"Node {ABSENT} did not answer" in note for note in job.notes)


def test_read_all_asks_again_what_a_busy_node_answered_too_late(bench: Bench) -> None:
    """Two answers later than the SDO timeout (a busy machine), then normal answers: every parameter is read,
    the two late ones at the end, and the job names them."""
    parameters.configure(bench.session, parameters.SdoSettings(timeout_s=0.3, retries=0, use_sdo2=False))
    bench.plant.nodes[5].faults.set(late_requests=2, latency_ms=700)
    first_two = [item.ref for item in parameters.readable_items(bench.session.node(5))[:2]]

    async def go() -> Any:
        job = parameters.start_read(bench.session, [5], bench.jobs, ctx=SERVICE)
        await job.wait()
        return job

    job = bench.run(go())
    assert job.state is JobState.DONE and job.failed == 0, (job.issues, job.notes)
    assert len(job.result["values"]["5"]) == job.total
    # the two late ones, and on a loaded machine maybe more
    assert job.result["retried"]["5"][:2] == first_two and job.result["failed_after_retry"]["5"] == []


def test_read_all_cancel_keeps_partial_result(bench: Bench) -> None:
    bench.plant.nodes[12].latency = type(bench.plant.nodes[12].latency)(0.01)

    async def go() -> Any:
        job = parameters.start_read(bench.session, [12], bench.jobs, ctx=SERVICE)
        version = 0
        while job.done < 20:
            version = await job.wait_change(version, timeout_s=5)
        progress = job.progress()
        assert progress.rate_per_s > 0 and progress.eta_s is not None
        bench.jobs.cancel(job.id)
        await job.wait()
        return job

    job = bench.run(go())
    assert job.state is JobState.CANCELLED
    kept = job.result["values"]["12"]
    assert 20 <= len(kept) < job.total
    assert parameters.service(bench.session).values[12].keys() >= kept.keys()


def test_read_group_reads_only_that_group(bench: Bench) -> None:
    async def go() -> Any:
        job = parameters.start_read(bench.session, [5], bench.jobs, group="Motor data", ctx=SERVICE)
        await job.wait()
        return job

    job = bench.run(go())
    refs = set(job.result["values"]["5"])
    assert "C00088" in refs and all(bench.session.node(5).catalog.resolve(r).group == "Motor data"  # type: ignore[union-attr]
                                    for r in refs)


def test_per_session_timeout_settings(bench: Bench) -> None:
    parameters.configure(bench.session, parameters.SdoSettings(timeout_s=0.05, retries=0))
    started = time.monotonic()
    with pytest.raises(SdoTimeoutError):
        bench.run(parameters.read(bench.session, ABSENT, "C00061"))
    assert time.monotonic() - started < 5
    assert bench.session.network.nodes[ABSENT].channels[0].client.RESPONSE_TIMEOUT == 0.05
    with pytest.raises(OutOfRange):
        parameters.configure(bench.session, parameters.SdoSettings(timeout_s=0, retries=0))
