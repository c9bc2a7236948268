"""A server killed in the middle of a PDO recording: the next server on the same database restores, from the restore
record the recording wrote before it changed anything, every TPDO setting and the NMT state it changed on the
node (the plant runs on, outside both servers, as a real machine would)."""

from __future__ import annotations

from fastapi.testclient import TestClient

from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.scope import pdo_source, restore_record
from drivebench.services.scope.pdo_plan import plan_recording
from drivebench.services.scope.pdo_source import PdoScopeSource
from drivebench.services.scope.source import ScopeChannel
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import wait_until
from tests.write_contexts import SERVICE

NODE = 7
TPDO3 = [(0x1802, sub) for sub in (1, 2, 3, 5)] + [(0x1A02, sub) for sub in range(5)]


def _values(plant: Plant) -> dict[tuple[int, int], object]:
    store = plant.nodes[NODE].store
    return {(index, sub): store.get(index, sub) for index, sub in TPDO3}


def test_a_new_server_restores_what_a_killed_recording_left(plant: Plant, channel: str, app_db_url: str) -> None:
    bus = f"virtual:{channel}@500000"
    before = _values(plant)
    with TestClient(create_app(buses=[bus])) as first:
        session = first.app.state.drivebench.manager.list()[0]  # type: ignore[attr-defined]
        session.add_node(NODE, plant.nodes[NODE].profile.id)
        plan = first.portal.call(plan_recording, session, [ScopeChannel(NODE, "0x6064")], 0.002)
        needed = pdo_source.confirmation(plan)
        assert needed is not None
        source = PdoScopeSource(session, plan, SERVICE.confirming(Confirmation(needed[0], needed[2])))
        frames: list[object] = []
        first.portal.call(source.start, frames.append, print)
        assert wait_until(lambda: len(frames) > 20, 10)
        # killed: the server goes away without stopping the recording
    assert wait_until(lambda: plant.nodes[NODE].state.name == "OPERATIONAL", 2)
    assert _values(plant) != before, "the recording had remapped TPDO3"
    assert len(restore_record.leftovers()) == 1

    with TestClient(create_app(buses=[bus])):
        assert _values(plant) == before
        assert wait_until(lambda: plant.nodes[NODE].state.name == "PRE_OPERATIONAL", 5)
        assert restore_record.leftovers() == [], "removed after a good read-back"
