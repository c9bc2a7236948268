"""The event-loop expedited (and, when asked, segmented) SDO upload against the simulated demo drives on a real
virtual CAN bus."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator

import can
import pytest

from drivebench.errors import ProtocolError, SdoAbortError, SdoOutOfStepError, SdoStalledError, SdoTimeoutError
from drivebench.protocol.canopen.network import CanopenNetwork
from drivebench.protocol.canopen.sdo_fast import ExpeditedRequest, upload_batch, upload_expedited, uploader
from drivebench.simulator.plant import Plant
from drivebench.transport.bus import BusSpec, open_bus

MOTEC = 5  # Lenze 8400 motec in the demo plant
ABSENT = 40
C00061 = ExpeditedRequest(0x5FC2, 0)  # Lenze code = 0x5FFF - code number (8400 motec ch. 12)
C00099 = ExpeditedRequest(0x5F9C, 0)  # 11-character firmware string: the device answers segmented
SEGMENTS = 2  # of C00099: 7 + 4 characters


@pytest.fixture
def network(plant: Plant, channel: str) -> Iterator[CanopenNetwork]:
    master = CanopenNetwork(open_bus(BusSpec.parse(f"virtual:{channel}@500000")), sdo_timeout_s=0.3,
                            sdo_retries=0)
    yield master
    master.close()


def frames_to(wire: can.BusABC, node_id: int) -> list[bytes]:
    """The frames sent so far to the node's first SDO channel (client -> server)."""
    sent = []
    while (msg := wire.recv(timeout=0.05)) is not None:
        if msg.arbitration_id == 0x600 + node_id:
            sent.append(bytes(msg.data))
    return sent


def test_expedited_answer_is_the_value_bytes(plant: Plant, network: CanopenNetwork, wire: can.BusABC) -> None:
    plant.nodes[MOTEC].store.set_ref("C00061", 43)
    data = asyncio.run(upload_expedited(network.node(MOTEC), C00061))
    assert data == (43).to_bytes(4, "little")
    assert frames_to(wire, MOTEC) == [bytes.fromhex("40 C2 5F 00 00 00 00 00")]


def test_device_abort_raises_the_abort_code(network: CanopenNetwork) -> None:
    with pytest.raises(SdoAbortError) as caught:
        asyncio.run(upload_expedited(network.node(MOTEC), ExpeditedRequest(0x2FFF, 0)))
    assert (caught.value.abort_code, caught.value.node) == (0x06020000, MOTEC)


def test_segmented_answer_is_left_to_the_blocking_client(network: CanopenNetwork, wire: can.BusABC) -> None:
    """None, and the started segmented transfer is aborted (0x05040001) so the device is ready again."""
    client = network.node(MOTEC)
    assert asyncio.run(upload_expedited(client, C00099)) is None
    assert frames_to(wire, MOTEC) == [bytes.fromhex("40 9C 5F 00 00 00 00 00"),
                                      bytes.fromhex("80 9C 5F 00 01 00 04 05")]
    assert len(client.upload(0x5F9C, 0)) > 4
    assert not client.channels[0].lock.locked()


def test_segmented_answer_is_read_on_the_loop_when_asked(network: CanopenNetwork, wire: can.BusABC) -> None:
    """segmented=True: the segments are asked for on the event loop (toggle 0, 1, ...), the value is the one the
    blocking client reads, and no abort is sent."""
    client = network.node(MOTEC)
    data = asyncio.run(upload_expedited(client, C00099, segmented=True))
    assert data is not None and len(data) > 7
    sent = frames_to(wire, MOTEC)
    assert sent[0] == bytes.fromhex("40 9C 5F 00 00 00 00 00")
    assert sent[1:] == [bytes([0x60 | (n % 2) << 4]) + bytes(7) for n in range(len(sent) - 1)]
    assert len(sent) - 1 == -(-len(data) // 7), "one request per segment"
    assert client.upload(0x5F9C, 0) == data
    assert not client.channels[0].lock.locked()


def test_the_segments_are_asked_for_while_the_event_loop_is_busy(network: CanopenNetwork, wire: can.BusABC) -> None:
    """The bus reader thread asks for each segment as the previous one arrives: while the loop stands still
    (a long synchronous step of another task) the whole transfer goes by on the bus, and the loop wakes once."""
    client = network.node(MOTEC)

    async def go() -> tuple[list[bytes], bytes | None]:
        reading = asyncio.ensure_future(upload_expedited(client, C00099, segmented=True))
        await asyncio.sleep(0)  # the read sends its initiate request and waits
        sent_meanwhile: list[bytes] = []  # the loop is busy here: nothing on it runs
        deadline = time.monotonic() + 10
        while len(sent_meanwhile) < 1 + SEGMENTS and time.monotonic() < deadline:
            sent_meanwhile += frames_to(wire, MOTEC)
        return sent_meanwhile, await reading

    sent, data = asyncio.run(go())
    assert data is not None and data == client.upload(0x5F9C, 0)
    assert -(-len(data) // 7) == SEGMENTS
    assert sent == [bytes.fromhex("40 9C 5F 00 00 00 00 00")] + [bytes([0x60 | (n % 2) << 4]) + bytes(7)
                                                                  for n in range(SEGMENTS)]


def test_segments_out_of_step_abort_the_transfer(plant: Plant, network: CanopenNetwork, wire: can.BusABC) -> None:
    plant.nodes[MOTEC].faults.set(wrong_toggle=True)
    with pytest.raises(SdoOutOfStepError) as caught:
        asyncio.run(upload_expedited(network.node(MOTEC), C00099, segmented=True))
    assert caught.value.reason == "toggle"
    assert frames_to(wire, MOTEC)[-1] == bytes.fromhex("80 9C 5F 00 00 00 03 05")  # CiA 301 0x05030000
    plant.nodes[MOTEC].faults.set(wrong_toggle=False, silent_after_segments=1)
    with pytest.raises(SdoStalledError) as stalled:
        asyncio.run(upload_expedited(network.node(MOTEC), C00099, segmented=True))
    assert (stalled.value.done, stalled.value.total) == (1, 2)
    assert frames_to(wire, MOTEC)[-1] == bytes.fromhex("80 9C 5F 00 00 00 04 05")  # timed out: 0x05040000


def test_busy_channel_is_left_to_the_blocking_client(network: CanopenNetwork, wire: can.BusABC) -> None:
    client = network.node(MOTEC)
    with client.channels[0].lock:
        assert asyncio.run(upload_expedited(client, C00061, channel=1)) is None
    assert frames_to(wire, MOTEC) == []


def test_timeout_retries_then_aborts(network: CanopenNetwork, wire: can.BusABC) -> None:
    """With one retry the request goes out twice; then the transfer is aborted (CiA 301 0x05040000)."""
    client = network.node(ABSENT)
    client.configure(0.1, 1)
    with pytest.raises(SdoTimeoutError) as caught:
        asyncio.run(upload_expedited(client, C00061))
    assert (caught.value.node, caught.value.index, caught.value.subindex) == (ABSENT, 0x5FC2, 0)
    request = bytes.fromhex("40 C2 5F 00 00 00 00 00")
    assert frames_to(wire, ABSENT) == [request, request, bytes.fromhex("80 C2 5F 00 00 00 04 05")]
    assert not client.channels[0].lock.locked()


def test_cancel_releases_the_channel(plant: Plant, network: CanopenNetwork) -> None:
    plant.nodes[MOTEC].store.set_ref("C00061", 43)
    absent = network.node(ABSENT)
    absent.configure(5.0, 0)

    async def go() -> tuple[bool, bytes | None]:
        waiting = asyncio.ensure_future(upload_expedited(absent, C00061))
        await asyncio.sleep(0.05)
        waiting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiting
        lock_free = not absent.channels[0].lock.locked()
        other = await upload_expedited(network.node(MOTEC), C00061)
        return lock_free, other

    assert asyncio.run(go()) == (True, (43).to_bytes(4, "little"))
    absent.configure(0.05, 0)  # the cancelled channel takes a new transfer (no stale pending answer)
    with pytest.raises(SdoTimeoutError):
        asyncio.run(upload_expedited(absent, C00061))


def test_one_uploader_per_channel(network: CanopenNetwork) -> None:
    client = network.node(MOTEC)
    second = client.add_channel(0x640 + MOTEC, 0x5C0 + MOTEC)
    assert uploader(client, 1) is uploader(client, 1)
    assert uploader(client, 2) is not uploader(client, 1)
    assert uploader(client, 2).sdo is second.client


# --- batches: the next request sent by the bus reader thread as soon as an answer ends the one before ---------------
MISSING = ExpeditedRequest(0x2FFF, 0)
ABORT_NOT_THERE = 0x06020000
SEGMENT_REQUESTS = [bytes([0x60 | (n % 2) << 4]) + bytes(7) for n in range(SEGMENTS)]


def test_a_batch_goes_by_on_the_bus_while_the_event_loop_is_busy(plant: Plant, network: CanopenNetwork,
                                                                wire: can.BusABC) -> None:
    """An expedited value, a segmented string, an object the device does not have and the first one again: every
    request goes out in order without the loop (it stands still meanwhile), each answer is its own result."""
    plant.nodes[MOTEC].store.set_ref("C00061", 43)
    client = network.node(MOTEC)
    batch = [C00061, C00099, MISSING, C00061]

    async def go() -> tuple[list[bytes], list[bytes | ProtocolError | None] | None]:
        reading = asyncio.ensure_future(upload_batch(client, batch, [False, True, False, False]))
        await asyncio.sleep(0)
        sent: list[bytes] = []
        expected = len(batch) + SEGMENTS
        deadline = time.monotonic() + 10
        while len(sent) < expected and time.monotonic() < deadline:
            sent += frames_to(wire, MOTEC)
        return sent, await reading

    sent, results = asyncio.run(go())
    assert results is not None
    assert results[0] == results[3] == (43).to_bytes(4, "little")
    assert results[1] == client.upload(0x5F9C, 0)
    assert isinstance(results[2], SdoAbortError) and results[2].abort_code == ABORT_NOT_THERE
    initiate = [request.frame for request in batch]
    assert sent == [initiate[0], initiate[1], *SEGMENT_REQUESTS, initiate[2], initiate[3]]
    assert not client.channels[0].lock.locked()


def test_a_batch_goes_on_after_a_transfer_that_failed(plant: Plant, network: CanopenNetwork, wire: can.BusABC) -> None:
    """A segment out of step or a stalled transfer is aborted and is that object's error; the next one is read."""
    plant.nodes[MOTEC].store.set_ref("C00061", 43)
    client = network.node(MOTEC)
    plant.nodes[MOTEC].faults.set(wrong_toggle=True)
    results = asyncio.run(upload_batch(client, [C00099, C00061], [True, False]))
    assert results is not None and isinstance(results[0], SdoOutOfStepError) and results[0].reason == "toggle"
    assert results[1] == (43).to_bytes(4, "little")
    sent = frames_to(wire, MOTEC)
    assert bytes.fromhex("80 9C 5F 00 00 00 03 05") in sent  # CiA 301 0x05030000 before the next request
    assert sent.index(bytes.fromhex("80 9C 5F 00 00 00 03 05")) < sent.index(C00061.frame)
    plant.nodes[MOTEC].faults.set(wrong_toggle=False, silent_after_segments=1)
    client.configure(1.0, 0)  # the device's answers are in well before this on a loaded machine; its silence is not
    results = asyncio.run(upload_batch(client, [C00099, C00061], [True, False]))
    assert results is not None and isinstance(results[0], SdoStalledError)
    assert (results[0].done, results[0].total) == (1, 2)
    assert results[1] == (43).to_bytes(4, "little")


def test_a_lost_request_in_a_batch_is_sent_again_and_a_silent_node_times_out_per_object(
        plant: Plant, network: CanopenNetwork, wire: can.BusABC) -> None:
    plant.nodes[MOTEC].store.set_ref("C00061", 43)
    client = network.node(MOTEC)
    client.configure(1.0, 1)
    plant.nodes[MOTEC].faults.set(drop_requests=1)
    results = asyncio.run(upload_batch(client, [C00061, C00061], [False, False]))
    assert results == [(43).to_bytes(4, "little")] * 2
    assert frames_to(wire, MOTEC) == [C00061.frame] * 3  # the first one twice: it got no answer
    absent = network.node(ABSENT)
    absent.configure(0.05, 0)
    results = asyncio.run(upload_batch(absent, [C00061, C00099], [False, True]))
    assert results is not None and all(isinstance(result, SdoTimeoutError) for result in results)
    assert frames_to(wire, ABSENT) == [C00061.frame, bytes.fromhex("80 C2 5F 00 00 00 04 05"),
                                       C00099.frame, bytes.fromhex("80 9C 5F 00 00 00 04 05")]


# --- a busy node: its answers come late, in the order the requests came ---------------------------------------------
BUSY = 41
COB_SUB1, COB_SUB2 = ExpeditedRequest(0x1800, 1), ExpeditedRequest(0x1800, 2)


def _answer(request: ExpeditedRequest, value: int) -> can.Message:
    return can.Message(arbitration_id=0x580 + BUSY, data=b"\x43" + request.address + value.to_bytes(4, "little"),
                       is_extended_id=False)


def _busy_node(bus: can.BusABC, timeout_s: float, done: threading.Event) -> None:
    """Answers 0x1800 sub 1 and sub 2 as a node on a loaded machine does: late, and in the order the requests came.
    The first request for sub 1 is answered only once the retry came; the retry's answer (a late duplicate) comes
    0.6 timeouts after the second request for sub 2, and the answer for sub 2 0.7 timeouts after that: later than
    that request's own timeout, but soon after the node's previous (late) answer."""
    received = 0
    while not done.is_set() and received < 4:
        msg = bus.recv(timeout=0.1)
        if msg is None or msg.arbitration_id != 0x600 + BUSY or msg.data[0] != 0x40:  # initiate upload requests
            continue
        received += 1
        if received == 2:
            bus.send(_answer(COB_SUB1, 0x180 + BUSY))  # the first request's answer, while the retry waits
    if received < 4:
        return
    time.sleep(0.6 * timeout_s)
    bus.send(_answer(COB_SUB1, 0x180 + BUSY))  # the retry's answer, while sub 2 is asked
    time.sleep(0.7 * timeout_s)
    bus.send(_answer(COB_SUB2, 1))


def test_a_busy_node_that_answers_late_and_in_order_is_read(channel: str, wire: can.BusABC) -> None:
    """A healthy node slowed down by a loaded machine (the scope start's "answer for 0x1800 sub 1 while 0x1800 sub 2
    was asked"): the late answer to the first request is taken while the retry waits, and a late answer to an
    earlier request while the next object is asked shows the node works through them in order, so the wait for
    this object's answer starts again from it instead of failing the read as out of step."""
    timeout_s = 1.0
    master = CanopenNetwork(open_bus(BusSpec.parse(f"virtual:{channel}@500000")), sdo_timeout_s=timeout_s,
                            sdo_retries=1)
    done = threading.Event()
    slave = can.Bus(interface="virtual", channel=channel)  # on the bus before the first request
    node = threading.Thread(target=_busy_node, args=(slave, timeout_s, done), daemon=True)
    node.start()
    try:
        client = master.node(BUSY)

        async def read_both() -> list[bytes | None]:
            return [await upload_expedited(client, COB_SUB1), await upload_expedited(client, COB_SUB2)]

        assert asyncio.run(read_both()) == [(0x180 + BUSY).to_bytes(4, "little"), (1).to_bytes(4, "little")]
        sent = frames_to(wire, BUSY)
        assert sent == [COB_SUB1.frame, COB_SUB1.frame, COB_SUB2.frame, COB_SUB2.frame], "no abort: both were read"
    finally:
        done.set()
        node.join(10)
        slave.shutdown()
        master.close()
