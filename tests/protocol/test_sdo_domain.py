"""Program images sent by DriveBench's block/segmented DOMAIN download (protocol/canopen/sdo_domain.py) over a real
python-can virtual bus: to the simulated drives, and to a CiA 302-3 slave on canopen's LocalNode that refuses block
transfer (tests/protocol/program_slave.py)."""

from __future__ import annotations

import os
import threading
import zlib
from collections.abc import Iterator
from contextlib import contextmanager

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen.sdo_domain import ABORT_BY_CLIENT, TransferCancelled, download_domain
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.conftest import fresh_channel, wait_until
from tests.protocol.program_slave import ProgramSlave
from tests.simulator.canopen_master import connected, remote

SERVO, FAN, SLAVE = 7, 12, 40
IMAGE = os.urandom(20_000)


@pytest.fixture
def bus_channel() -> str:
    return fresh_channel()


@pytest.fixture
def plant(registry: ProfileRegistry, bus_channel: str) -> Iterator[Plant]:
    plant_file = PlantFile(name="program download", bus=f"virtual:{bus_channel}@500000",
                           nodes=[PlantNode(node_id=SERVO, profile="generic-cia402-servo"),
                                  PlantNode(node_id=FAN, profile="lenze-8200-vector-emf2178ib")])
    running = Plant(plant_file, registry.get).start()
    yield running
    running.stop()


@pytest.fixture
def master(bus_channel: str, plant: Plant) -> Iterator[canopen.Network]:
    with connected(bus_channel) as network:
        yield network


def _stop_program(node: canopen.RemoteNode) -> None:
    node.sdo.download(0x1F51, 1, b"\x00")


def test_block_download_lands_and_0x1F56_names_the_new_image(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, SERVO)
    _stop_program(node)
    seen: list[int] = []
    assert download_domain(node.sdo, 0x1F50, 1, IMAGE, progress=seen.append) == "block"
    assert plant.nodes[SERVO].program.image == IMAGE
    assert seen[-1] == len(IMAGE) and seen == sorted(seen) and len(seen) > 3
    node.sdo.download(0x1F51, 1, b"\x01")
    assert int.from_bytes(node.sdo.upload(0x1F56, 1), "little") == zlib.crc32(IMAGE)
    assert node.sdo.upload(0x1F57, 1) == bytes(4)


def test_faults_on_transfer_starts_leave_block_segments_alone(master: canopen.Network, plant: Plant) -> None:
    # a block segment starts with its sequence number: 0x21 reads like an initiate download, 0xA2 like a block upload
    # ack; a fault that aborts every second transfer start must abort the upload after the download, not a segment
    node = remote(master, SERVO)
    _stop_program(node)
    plant.nodes[SERVO].faults.set(abort_code=0x08000020, abort_every=2)
    assert download_domain(node.sdo, 0x1F50, 1, IMAGE) == "block"
    assert plant.nodes[SERVO].program.image == IMAGE
    with pytest.raises(SdoAbortedError) as aborted:
        node.sdo.upload(0x1F56, 1)
    assert aborted.value.code == 0x08000020


def test_a_device_without_block_transfer_gets_it_segmented(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, FAN)
    _stop_program(node)
    assert download_domain(node.sdo, 0x1F50, 1, IMAGE[:3000]) == "segmented"
    assert plant.nodes[FAN].program.image == IMAGE[:3000]


def test_a_slow_device_is_waited_for_not_given_up(master: canopen.Network, plant: Plant) -> None:
    """Every answer comes later than the session's SDO timeout (0.5 s): a device in the middle of a transfer it
    accepted is there, and the download waits for its answers (a loaded host answers late too)."""
    node = remote(master, FAN)
    _stop_program(node)
    node.sdo.RESPONSE_TIMEOUT = 0.5
    plant.nodes[FAN].faults.set(latency_ms=650)  # the simulator drops a transfer idle for 1 s
    assert download_domain(node.sdo, 0x1F50, 1, IMAGE[:20]) == "segmented"
    assert plant.nodes[FAN].program.image == IMAGE[:20]


@contextmanager
def _another_answer(bus_channel: str, node_id: int, after_request: int, data: bytes) -> Iterator[None]:
    """Another sender on the bus answers on ``node_id``'s SDO answer COB-ID right after the node's
    ``after_request``-th SDO request from now (1: the download's initiate)."""
    other = can.Bus(interface="virtual", channel=bus_channel, receive_own_messages=False)

    def answer() -> None:
        seen = 0
        while (frame := other.recv(timeout=30)) is not None:
            if frame.arbitration_id == 0x600 + node_id:
                seen += 1
                if seen == after_request:
                    other.send(can.Message(arbitration_id=0x580 + node_id, data=data, is_extended_id=False))
                    return

    sender = threading.Thread(target=answer, daemon=True)
    sender.start()
    try:
        yield
    finally:
        sender.join(timeout=30)
        other.shutdown()


def test_a_late_answer_to_an_earlier_request_is_not_taken_for_the_initiate_answer(
        master: canopen.Network, plant: Plant, bus_channel: str) -> None:
    """The answer to a write that its client sent again after a timeout arrives twice; the second, naming 0x1F51,
    comes while the download waits for its initiate answer and must not start the segments."""
    node = remote(master, FAN)
    _stop_program(node)
    node.sdo.RESPONSE_TIMEOUT = 0.5
    plant.nodes[FAN].faults.set(latency_ms=3000, late_requests=1)  # its own initiate answer comes well after
    with _another_answer(bus_channel, FAN, 1, b"\x60\x51\x1f\x01" + bytes(4)):  # names 0x1F51
        assert download_domain(node.sdo, 0x1F50, 1, IMAGE[:20], block=False) == "segmented"
    assert plant.nodes[FAN].program.image == IMAGE[:20]


def test_a_frame_too_short_to_name_an_object_is_passed_over_while_the_initiate_answer_is_awaited(
        master: canopen.Network, plant: Plant, bus_channel: str) -> None:
    """A two-byte frame on the node's SDO answer COB-ID (a broken device or another tool) while the download waits
    for its initiate answer names no object: it is passed over, not unpacked (it raised struct.error before)."""
    node = remote(master, FAN)
    _stop_program(node)
    plant.nodes[FAN].faults.set(latency_ms=300)  # its own initiate answer comes after the short frame
    with _another_answer(bus_channel, FAN, 1, b"\x60\x51"):
        assert download_domain(node.sdo, 0x1F50, 1, IMAGE[:20], block=False) == "segmented"
    assert plant.nodes[FAN].program.image == IMAGE[:20]


@pytest.mark.parametrize("block", [False, True])
def test_a_late_abort_of_another_object_does_not_end_the_transfer(
        master: canopen.Network, plant: Plant, bus_channel: str, block: bool) -> None:
    """A clean-clone run: a late "object does not exist" abort of another object (the answer to an earlier request
    its client had sent again) came in the middle of a program download and ended it ("The device refused the
    program ... 0x1F50sub1 ... 0x06020000"). Inside a transfer a frame that names an object must name this one."""
    target = SERVO if block else FAN  # the servo takes block transfers, the fan's device only segmented ones
    node = remote(master, target)
    _stop_program(node)
    if not block:  # each segment's own answer comes after the late abort (a sub-block's answer comes at its end)
        plant.nodes[target].faults.set(latency_ms=300)
    image = IMAGE[:70]  # ten segments: one short sub-block, so a loaded host's pause cannot outlast the device's wait
    stale_abort = b"\x80\x56\x1f\x00" + (0x06020000).to_bytes(4, "little")
    # after the first frame that follows the initiate: a segment, or the first of a sub-block
    with _another_answer(bus_channel, target, 2, stale_abort):
        done = download_domain(node.sdo, 0x1F50, 1, image, block=block)
    assert done == ("block" if block else "segmented")
    assert plant.nodes[target].program.image == image


def test_cancel_aborts_the_transfer_on_the_bus(master: canopen.Network, plant: Plant, bus_channel: str) -> None:
    node = remote(master, SERVO)
    _stop_program(node)
    spy = can.Bus(interface="virtual", channel=bus_channel, receive_own_messages=False)
    cancel = threading.Event()

    def progress(sent: int) -> None:
        if sent > 5000:
            cancel.set()

    try:
        with pytest.raises(TransferCancelled) as cancelled:
            download_domain(node.sdo, 0x1F50, 1, IMAGE, progress=progress, cancelled=cancel)
        aborts = []
        while (frame := spy.recv(timeout=0.5)) is not None:
            if frame.arbitration_id == 0x600 + SERVO and frame.data[0] == 0x80:
                aborts.append(bytes(frame.data))
    finally:
        spy.shutdown()
    assert cancelled.value.code == ABORT_BY_CLIENT
    assert aborts == [b"\x80\x50\x1f\x01" + ABORT_BY_CLIENT.to_bytes(4, "little")]
    assert plant.nodes[SERVO].program.image != IMAGE  # nothing of the cut transfer was flashed
    assert node.sdo.upload(0x1F51, 1) == b"\x00"  # and the device answers again at once


def test_a_running_program_refuses_the_download(master: canopen.Network) -> None:
    node = remote(master, SERVO)
    with pytest.raises(SdoAbortedError) as refused:
        download_domain(node.sdo, 0x1F50, 1, IMAGE[:700])
    assert refused.value.code == 0x08000022


def test_independent_localnode_slave_falls_back_to_segmented() -> None:
    channel = fresh_channel()
    with connected(channel) as slave_network, connected(channel) as master:
        slave = ProgramSlave(slave_network, SLAVE)
        node = remote(master, SLAVE)
        node.sdo.download(0x1F51, 1, b"\x00")
        assert not slave.running
        assert download_domain(node.sdo, 0x1F50, 1, IMAGE[:5000]) == "segmented"
        assert slave.image == IMAGE[:5000]
        node.sdo.download(0x1F51, 1, b"\x01")
        assert wait_until(lambda: slave.running, 5)
        assert int.from_bytes(node.sdo.upload(0x1F56, 1), "little") == zlib.adler32(IMAGE[:5000])
