"""Sampling by PDO against a slave that shares no code with DriveBench's simulator: canopen's LocalNode (its SDO
server and NMT slave) with the object dictionary of the generic CiA 402 servo's EDS, sending its synchronous TPDOs
as its own 0x1800/0x1A00 objects say. Its position ramps by 10 increments per SYNC."""

from __future__ import annotations

import asyncio
import itertools
import struct
import threading
import time
from collections.abc import Callable, Iterator

import canopen
import pytest

from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.scope import pdo_source
from drivebench.services.scope.pdo_plan import plan_recording
from drivebench.services.scope.pdo_source import PdoScopeSource
from drivebench.services.scope.source import ScopeChannel, ScopeFrame
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage import database
from tests.conftest import fresh_channel, wait_until
from tests.write_contexts import SERVICE

NODE = 9
STEP = 10
TPDO3 = [(0x1802, sub) for sub in (1, 2, 3, 5)] + [(0x1A02, sub) for sub in range(5)]


class SyncSlave:
    """A CiA 301 slave of canopen's LocalNode that sends, on each SYNC while operational, every valid TPDO with a
    synchronous transmission type (1-240: every n-th SYNC), packed from its mapping."""

    def __init__(self, channel: str) -> None:
        self.network = canopen.Network()
        self.network.connect(interface="virtual", channel=channel, receive_own_messages=False)
        eds = settings.profiles_dir / "eds" / "generic-cia402-servo.eds"
        self.node = canopen.LocalNode(NODE, canopen.import_od(str(eds), NODE))
        self.network.add_node(self.node)
        self.node.nmt.state = "PRE-OPERATIONAL"
        self.syncs: dict[int, int] = {}
        self.position = 0
        self.lock = threading.Lock()
        self.network.subscribe(0x080, self.on_sync)

    def u(self, index: int, sub: int) -> int:
        return int.from_bytes(self.node.get_data(index, sub), "little")

    def on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.lock:
            self.position += STEP
            self.node.set_data(0x6064, 0, struct.pack("<i", self.position))
            if self.node.nmt.state != "OPERATIONAL":
                return
            for number in range(4):
                comm, mapping = 0x1800 + number, 0x1A00 + number
                if comm not in self.node.object_dictionary:
                    continue
                cob, kind = self.u(comm, 1), self.u(comm, 2)
                if cob & 0x8000_0000 or not 1 <= kind <= 240:
                    continue
                self.syncs[number] = self.syncs.get(number, 0) + 1
                if self.syncs[number] % kind:
                    continue
                value, offset = 0, 0
                for sub in range(1, self.u(mapping, 0) + 1):
                    entry = self.u(mapping, sub)
                    bits = entry & 0xFF
                    field = int.from_bytes(self.node.get_data(entry >> 16, (entry >> 8) & 0xFF), "little")
                    value |= (field & ((1 << bits) - 1)) << offset
                    offset += bits
                self.network.send_message(cob & 0x7FF, value.to_bytes(offset // 8, "little"))

    def values(self) -> dict[tuple[int, int], int]:
        return {(index, sub): self.u(index, sub) for index, sub in TPDO3}

    def close(self) -> None:
        self.network.disconnect()


@pytest.fixture
def slave_session(registry: ProfileRegistry, app_db_url: str) -> Iterator[tuple[asyncio.Runner, Session, SyncSlave]]:
    database.upgrade_to_head(app_db_url)
    channel = fresh_channel()
    slave = SyncSlave(channel)
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    session = runner.run(manager.open(f"virtual:{channel}@500000", "localnode"))
    session.add_node(NODE, "generic-cia402-servo")
    yield runner, session, slave
    runner.run(manager.close_all())
    runner.close()
    slave.close()


def _record(runner: asyncio.Runner, session: Session, during: Callable[[list[ScopeFrame]], None] = lambda _f: None
            ) -> tuple[list[tuple[int, int]], list[str]]:
    """A recording of the slave's position and status word at 2 ms; ``during`` runs once 50 samples came."""
    plan = runner.run(plan_recording(session, [ScopeChannel(NODE, "0x6064"), ScopeChannel(NODE, "0x6041")], 0.002))
    assert [(t.node, t.number) for t in plan.tpdos] == [(NODE, 3)]
    needed = pdo_source.confirmation(plan)
    assert needed is not None
    source = PdoScopeSource(session, plan, SERVICE.confirming(Confirmation(needed[0], needed[2])))
    frames: list[ScopeFrame] = []
    runner.run(source.start(frames.append, print))
    values = lambda: sum(f.raw[0] is not None for f in frames)  # noqa: E731
    assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or values() > 50, 15)
    during(frames)
    seen = values()
    assert wait_until(lambda: runner.run(asyncio.sleep(0.05)) or values() > seen + 50, 15)
    texts = runner.run(source.stop())
    return [(f.sample, f.raw[0]) for f in frames if f.raw[0] is not None], texts


def _consecutive(got: list[tuple[int, int]]) -> None:
    samples = [sample for sample, _value in got]
    assert samples == list(range(samples[0], samples[0] + len(samples))), "one sample per SYNC, consecutive"
    assert all(later - earlier == STEP for (_a, earlier), (_b, later) in itertools.pairwise(got)), \
        "the slave's ramp, one step per SYNC"


def test_a_recording_from_a_localnode_slave(slave_session: tuple[asyncio.Runner, Session, SyncSlave]) -> None:
    runner, session, slave = slave_session
    before = slave.values()
    got, texts = _record(runner, session)
    _consecutive(got)
    assert slave.values() == before, texts
    assert slave.node.nmt.state == "PRE-OPERATIONAL"


def test_a_slave_that_stalls_answers_the_syncs_it_missed_and_each_is_numbered_by_its_sync(
        slave_session: tuple[asyncio.Runner, Session, SyncSlave]) -> None:
    """A loaded machine: the slave's thread gets no CPU for 0.3 s (150 SYNCs) while SYNC goes on, then answers the
    queued SYNCs in a burst. Each answer is the sample of the SYNC it answers (the old 50 ms wait numbered the
    burst from the newest SYNC: a jump of ~125 samples)."""
    runner, session, slave = slave_session

    def stall(_frames: list[ScopeFrame]) -> None:
        with slave.lock:
            time.sleep(0.3)

    got, _texts = _record(runner, session, stall)
    _consecutive(got)
