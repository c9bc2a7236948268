"""A healthy but slow node answers a request that its client sent again after a timeout twice (issue 29): the second,
late answer must not be taken for the answer to the next request. Through DriveBench's NodeClient (canopen's
blocking SDO client behind protocol/canopen/sdo_client.py) over a real python-can virtual bus, to the simulator and to
a slave on canopen's LocalNode (tests/protocol/program_slave.py, no code shared with the simulator)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import can
import pytest

from drivebench.protocol.canopen.network import CanopenNetwork
from drivebench.simulator.plant import Plant
from drivebench.simulator.program_store import RUNNING
from drivebench.transport.bus import BusSpec, open_bus
from tests.conftest import fresh_channel
from tests.protocol.program_slave import ProgramSlave
from tests.simulator.canopen_master import connected

FAN, SLAVE = 12, 40
TIMEOUT_S, LATE_S = 1.0, 1.5
"""Each late answer comes half a timeout after the attempt gave up: the read is sent again, and the node (answering
one request after the other) answers that second read only while the write after it waits."""


def _master(channel: str) -> CanopenNetwork:
    return CanopenNetwork(open_bus(BusSpec.parse(f"virtual:{channel}@500000")), sdo_timeout_s=TIMEOUT_S,
                          sdo_retries=2)


@pytest.fixture
def network(plant: Plant, channel: str) -> Iterator[CanopenNetwork]:
    master = _master(channel)
    yield master
    master.close()


def test_a_write_after_a_read_answered_late_succeeds_and_reads_back(network: CanopenNetwork, plant: Plant) -> None:
    node = network.node(FAN)
    assert node.upload(0x1F51, 1) == b"\x01"  # the program runs
    plant.nodes[FAN].faults.set(latency_ms=LATE_S * 1000, late_requests=2)  # the read and its second attempt
    node.upload(0x1F56, 1)
    node.download(0x1F51, 1, b"\x00")  # stop: the late second answer to the read (0x43 ... 0x1F56) comes meanwhile
    assert node.upload(0x1F51, 1) == b"\x00"
    assert plant.nodes[FAN].program.state != RUNNING


class SlowProgramSlave(ProgramSlave):
    """Its SDO server (the slave network's reader thread) is held for ``LATE_S`` on the next ``late`` reads."""

    def __init__(self, network: object, node_id: int) -> None:
        super().__init__(network, node_id)  # type: ignore[arg-type]
        self.late = 0
        self._lock = threading.Lock()

    def _read(self, index: int, subindex: int, od: object) -> int | None:
        with self._lock:
            slow, self.late = self.late > 0, max(self.late - 1, 0)
        if slow:
            threading.Event().wait(LATE_S)  # a busy device: the frames behind this one wait on the bus
        return super()._read(index, subindex, od)


def test_independent_localnode_slave_answering_late() -> None:
    channel = fresh_channel()
    with connected(channel) as slave_network:
        slave = SlowProgramSlave(slave_network, SLAVE)
        master = _master(channel)
        try:
            node = master.node(SLAVE)
            slave.late = 2
            node.upload(0x1F56, 1)
            node.download(0x1F51, 1, b"\x00")
            assert node.upload(0x1F51, 1) == b"\x00"
            assert not slave.running
        finally:
            master.close()


def test_an_abort_naming_another_object_is_not_taken_for_the_answer(network: CanopenNetwork, plant: Plant,
                                                                     channel: str) -> None:
    """A late abort of an earlier transfer (naming 0x1F56) arrives before the slow node's answer for 0x1F51."""
    node = network.node(FAN)
    plant.nodes[FAN].faults.set(latency_ms=TIMEOUT_S * 500, late_requests=1)  # answered within the attempt
    stale = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)

    def abort_other() -> None:
        while (frame := stale.recv(timeout=30)) is not None:
            if frame.arbitration_id == 0x600 + FAN and bytes(frame.data[:4]) == b"\x40\x51\x1f\x01":
                timed_out = 0x05040000  # CiA 301 "SDO protocol timed out"
                stale.send(can.Message(arbitration_id=0x580 + FAN, data=b"\x80\x56\x1f\x01" + timed_out.to_bytes(
                    4, "little"), is_extended_id=False))
                return

    sender = threading.Thread(target=abort_other, daemon=True)
    sender.start()
    try:
        assert node.upload(0x1F51, 1) == b"\x01"
    finally:
        sender.join(timeout=30)
        stale.shutdown()
