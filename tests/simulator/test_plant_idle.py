"""An idle simulated plant sleeps until a deadline or a change (issue 21 item 4): no 2 ms polling loop."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.simulator.ticker import MAX_SLEEP_S
from tests.conftest import DEMO_PLANT, fresh_channel, wait_until

WATCH_S = 2.0


@pytest.fixture
def plant_and_wire(registry: ProfileRegistry) -> Iterator[tuple[Plant, can.BusABC]]:
    channel = fresh_channel()
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    plant = Plant(PlantFile.load(DEMO_PLANT), registry.get, bus=f"virtual:{channel}@500000", latency="0ms").start()
    try:
        yield plant, wire
    finally:
        plant.stop()
        wire.shutdown()


def test_an_idle_plant_ticks_at_its_heartbeat_deadlines_not_in_a_loop(plant_and_wire: tuple[Plant, can.BusABC]
                                                                    ) -> None:
    plant, wire = plant_and_wire
    ticks: Counter[int] = Counter()
    for node in plant.nodes.values():
        def counted(now: float, node_id: int = node.node_id, tick=node.tick) -> float | None:  # type: ignore[no-untyped-def]
            ticks[node_id] += 1
            return tick(now)  # type: ignore[no-any-return]
        node.tick = counted  # type: ignore[method-assign]
    time.sleep(0.6)  # boot-up settled (the drives' first cycles: not ready -> switch on disabled)
    ticks.clear()
    while wire.recv(0) is not None:
        pass
    heartbeats: Counter[int] = Counter()
    end = time.monotonic() + WATCH_S
    while (left := end - time.monotonic()) > 0:
        msg = wire.recv(left)
        if msg is not None and 0x701 <= msg.arbitration_id <= 0x77F:
            heartbeats[msg.arbitration_id - 0x700] += 1
    # 0x1017 = 500 ms on each of the drives: 4 heartbeats each in 2 s (±1 for where the window falls)
    assert all(3 <= heartbeats[node_id] <= 5 for node_id in plant.nodes), heartbeats
    # one tick of every node per heartbeat of any node (the old ticker: 1,000 per node in 2 s)
    assert all(count <= len(plant.nodes) * 5 + 3 for count in ticks.values()), ticks


def test_a_write_wakes_the_sleeping_plant_at_once(plant_and_wire: tuple[Plant, can.BusABC]) -> None:
    """NMT start, then a changed mapped value: the change-driven TPDO goes out without waiting for a timer."""
    plant, wire = plant_and_wire
    node = plant.nodes[5]
    time.sleep(0.6)
    wire.send(can.Message(arbitration_id=0x000, data=bytes([0x01, 5]), is_extended_id=False))
    wait_until(lambda: node.state.name == "OPERATIONAL")
    tpdos = [config for config in node.pdo.tpdos if config.trans_type >= 254 and config.mapping]
    assert tpdos, "the 8400's profile maps an event-driven TPDO"
    while wire.recv(0.2) is not None:
        pass
    index, sub = tpdos[0].mapping[0][:2]
    node.store.set(index, sub, 0x1234 if node.store.get(index, sub) != 0x1234 else 0x4321)
    started = time.monotonic()
    msg = wire.recv(0.5)
    while msg is not None and msg.arbitration_id != tpdos[0].cob_id:
        msg = wire.recv(0.5)
    assert msg is not None and time.monotonic() - started < 0.5


def test_an_idle_ethercat_line_sleeps_until_a_slave_names_a_deadline_or_wakes_it(registry: ProfileRegistry) -> None:
    """The simulated master's slaves at rest are ticked about once a second (the old ticker: every 10 ms), and a
    change (a mailbox write wakes the slave's node) is taken up at once."""
    profile = registry.get("lenze-8400-motec-ethercat")
    slaves = [SimulatedSlave(profile, 1001, 0), SimulatedSlave(profile, 1002, 1)]
    ticks: Counter[int] = Counter()
    for slave in slaves:
        def counted(now: float, station: int = slave.station, tick=slave.tick) -> float | None:  # type: ignore[no-untyped-def]
            ticks[station] += 1
            return tick(now)  # type: ignore[no-any-return]
        slave.tick = counted  # type: ignore[method-assign]
    server = GatewayServer(slaves).start()
    try:
        time.sleep(0.3)  # start-up settled (Init -> Pre-Operational)
        ticks.clear()
        time.sleep(WATCH_S)
        assert all(ticks[slave.station] <= WATCH_S / MAX_SLEEP_S + 2 for slave in slaves), ticks
        last = ticks[1001]
        assert wait_until(lambda: ticks[1001] > last, MAX_SLEEP_S * 3)  # it has just ticked: asleep for ~1 s now
        slaves[0].node.wake()
        woken, last = time.monotonic(), ticks[1001]
        assert wait_until(lambda: ticks[1001] > last, MAX_SLEEP_S * 3)
        assert time.monotonic() - woken < MAX_SLEEP_S / 2
    finally:
        server.stop()
