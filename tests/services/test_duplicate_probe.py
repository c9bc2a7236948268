"""The duplicate-node probe after a scan, on a real virtual CAN bus with the simulated demo plant."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen.network import CanopenNetwork
from drivebench.services.bus.duplicates import DuplicateWatch
from drivebench.simulator.plant import Plant
from drivebench.transport.bus import BusSpec, open_bus

MOTEC = 5


@pytest.fixture
def network(plant: Plant, channel: str) -> Iterator[CanopenNetwork]:
    master = CanopenNetwork(open_bus(BusSpec.parse(f"virtual:{channel}@500000")), sdo_timeout_s=0.3, sdo_retries=0)
    master.node(MOTEC)
    yield master
    master.close()


def late_answer_during_probe(wire: can.BusABC, node_id: int, data: bytes) -> threading.Thread:
    """Sends ``data`` from the node's SDO server id as soon as the probe's request shows on the bus."""
    def answer() -> None:
        while (msg := wire.recv(timeout=2.0)) is not None:
            if msg.arbitration_id == 0x600 + node_id:
                wire.send(can.Message(arbitration_id=0x580 + node_id, data=data, is_extended_id=False))
                return
    sender = threading.Thread(target=answer, daemon=True)
    sender.start()
    return sender


def test_one_device_answers_once(network: CanopenNetwork) -> None:
    watch = DuplicateWatch()
    assert watch.probe(network, [MOTEC]) == {MOTEC: 1}
    assert watch.found() == {}


def test_a_late_answer_to_another_request_is_no_second_device(network: CanopenNetwork, wire: can.BusABC) -> None:
    """A duplicate's second answer to the scan's 0x1017 read may arrive while the probe listens: it answers another
    object, so it is no second answer to the probe (CI once reported "different serial numbers (0, 500)")."""
    sender = late_answer_during_probe(wire, MOTEC, bytes([0x4B, 0x17, 0x10, 0x00, 0xF4, 0x01, 0, 0]))
    watch = DuplicateWatch()
    assert watch.probe(network, [MOTEC]) == {MOTEC: 1}
    sender.join()
    assert watch.found() == {}


def test_two_devices_on_one_id_answer_twice(plant: Plant, registry: ProfileRegistry, network: CanopenNetwork) -> None:
    plant.add_node(registry.get("lenze-8400-motec-canopen"), MOTEC, duplicate=True, name="Second conveyor")
    watch = DuplicateWatch()
    assert watch.probe(network, [MOTEC]) == {MOTEC: 2}
    assert "2 answers to one SDO request" in watch.found()[MOTEC]


class HeldNotifier(can.Listener):
    """Holds the master's notifier thread at the first frame it sees until released: frames read after it wait in the
    bus's queue, as they do on a loaded machine whose notifier thread gets no CPU for a while."""

    def __init__(self) -> None:
        self.holding = threading.Event()
        self.release = threading.Event()

    def on_message_received(self, msg: can.Message) -> None:
        if not self.release.is_set():
            self.holding.set()
            self.release.wait(timeout=5.0)


def test_an_answer_sent_before_the_probe_asked_is_not_counted(network: CanopenNetwork, wire: can.BusABC) -> None:
    """CI once reported "3 answers to one SDO request" for two devices: a duplicate's second answer to the scan's own
    0x1018sub4 read was sent before the probe asked but reached the master's notifier only while the probe listened.
    An answer stamped before the request went out answers an earlier request."""
    held = HeldNotifier()
    network.add_listener(held)
    wire.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))  # the frame the notifier stops at
    assert held.holding.wait(timeout=5.0)
    serial = bytes([0x43, 0x18, 0x10, 0x04, 0x2A, 0, 0, 0])  # an answer to an earlier 0x1018sub4 read
    wire.send(can.Message(arbitration_id=0x580 + MOTEC, data=serial, is_extended_id=False))
    watch = DuplicateWatch()
    counted: dict[int, int] = {}
    prober = threading.Thread(target=lambda: counted.update(watch.probe(network, [MOTEC])))
    prober.start()
    try:
        # the probe's request shows on the wire only after the stale answer was stamped
        while (msg := wire.recv(timeout=5.0)) is not None and msg.arbitration_id != 0x600 + MOTEC:
            pass
        assert msg is not None, "the probe sent no request"
    finally:
        held.release.set()
        prober.join(timeout=10.0)
        network.remove_listener(held)
    assert counted == {MOTEC: 1}
    assert watch.found() == {}


def test_a_late_answer_to_the_scans_own_read_before_the_probe_asks_is_not_counted(network: CanopenNetwork,
                                                                                     wire: can.BusABC) -> None:
    """A duplicate whose SDO server was slow sends its second answer to the scan's own 0x1018sub4 read after the
    scan ended, while the probe gets ready: stamped after the probe's own request it would pass the stamp check (CI:
    "3 answers to one SDO request" for two devices). The probe first waits for quiet on the answer channels."""
    watch = DuplicateWatch()
    counted: dict[int, int] = {}
    prober = threading.Thread(target=lambda: counted.update(watch.probe(network, [MOTEC])))
    prober.start()
    time.sleep(0.05)
    wire.send(can.Message(arbitration_id=0x580 + MOTEC, data=bytes([0x43, 0x18, 0x10, 0x04, 0x2A, 0, 0, 0]),
                          is_extended_id=False))
    prober.join(timeout=10.0)
    assert counted == {MOTEC: 1}
    assert watch.found() == {}
