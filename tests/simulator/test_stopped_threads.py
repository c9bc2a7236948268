"""A stopped simulator leaves no thread of its own running (issue 29: the suite's process held hundreds of them)."""

from __future__ import annotations

import threading

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from drivebench.simulator.plant import Plant, PlantFile
from tests.conftest import DEMO_PLANT, fresh_channel


def _started_by(action: object) -> set[threading.Thread]:
    before = set(threading.enumerate())
    action()  # type: ignore[operator]
    return set(threading.enumerate()) - before


def test_a_stopped_idle_ethercat_gateway_ends_its_receiver(registry: ProfileRegistry) -> None:
    server = GatewayServer([SimulatedSlave(registry.get("lenze-8400-motec-ethercat"), 1001, 0)])
    threads = _started_by(server.start)
    assert {t.name for t in threads} >= {"sim-mbg-rx"}
    server.stop()
    assert [t.name for t in threads if t.is_alive()] == []


def test_a_stopped_plant_ends_its_threads(registry: ProfileRegistry) -> None:
    plant = Plant(PlantFile.load(DEMO_PLANT), registry.get, bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    threads = _started_by(plant.start)
    assert threads
    plant.stop()
    assert [t.name for t in threads if t.is_alive()] == []
