"""Stop commands outrank reads in a node's SDO queue (issue 27 item 7): on a real virtual bus with the simulated
plant, a quick stop queued behind 50 reads is the next request on the wire after the transfer in flight."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.control.drive_words import family_of
from drivebench.services.params import parameters
from drivebench.services.params.write_context import WriteContext
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile

NODE = 7
PLANT = {"name": "Stop queue plant", "nodes": [{"node_id": NODE, "profile": "generic-cia402-servo"}]}
READS = 50


@pytest.fixture
def rig(registry: ProfileRegistry, channel: str) -> Iterator[tuple[asyncio.Runner, Session, Plant, can.BusABC]]:
    plant = Plant(PlantFile.model_validate(PLANT), registry.get, bus=f"virtual:{channel}@500000",
                  latency="0ms").start()
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=20.0, sdo_retries=0)
    session = runner.run(manager.open(plant.spec, "stop-first"))
    session.add_node(NODE, "generic-cia402-servo")
    try:
        yield runner, session, plant, wire
    finally:
        runner.run(manager.close_all())
        runner.close()
        wire.shutdown()
        plant.stop()


async def _until(condition: object, what: str, seconds: float = 30.0) -> None:
    assert callable(condition)
    deadline = asyncio.get_running_loop().time() + seconds
    while not condition():
        assert asyncio.get_running_loop().time() < deadline, f"never: {what}"
        await asyncio.sleep(0.01)


def _requests(wire: can.BusABC) -> list[bytes]:
    found = []
    while (msg := wire.recv(timeout=0.2)) is not None:
        if msg.arbitration_id == 0x600 + NODE:
            found.append(bytes(msg.data))
    return found


def test_a_quick_stop_queued_behind_50_reads_is_the_next_request_after_the_one_in_flight(rig: tuple[
        asyncio.Runner, Session, Plant, can.BusABC]) -> None:
    runner, session, plant, wire = rig
    node = session.node(NODE)
    fam = family_of(node.catalog)
    assert fam is not None
    status = parameters.resolve(node, fam.status_ref)
    control = parameters.resolve(node, fam.control_ref)
    runner.run(parameters.read(session, NODE, fam.status_ref))  # the node answers; its channel exists
    _requests(wire)
    plant.nodes[NODE].faults.set(late_requests=1, latency_ms=3000)  # the first read stays in flight a while
    lock = session.network.nodes[NODE].channels[0].lock

    async def scenario() -> None:
        reads = [asyncio.create_task(parameters.read(session, NODE, fam.status_ref)) for _ in range(READS)]
        await _until(lambda: lock.waiting() == (0, READS - 1), "49 reads wait behind the one in flight")
        stop = asyncio.create_task(drive_guard.send_quick_stop(session, node, WriteContext.guard_stop()))
        await stop
        await asyncio.gather(*reads)

    runner.run(scenario())
    sent = _requests(wire)
    status_read = bytes([0x40, status.index & 0xFF, status.index >> 8, status.subindex])
    control_read = bytes([0x40, control.index & 0xFF, control.index >> 8, control.subindex])
    control_address = control_read[1:4]
    assert sent[0][:4] == status_read  # the read in flight
    assert sent[1][:4] == control_read  # the quick stop reads the control word it changes ...
    assert sent[2][0] & 0xE0 == 0x20 and sent[2][1:4] == control_address  # ... and writes it, nothing between
    assert [frame[:4] for frame in sent[3:]] == [status_read] * (READS - 1)  # then the reads that waited
