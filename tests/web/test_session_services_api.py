"""A session's services close with it through the real API: a running recording ends (its file complete), nothing
keeps the closed session alive, and a session opened again on the bus starts afresh."""

from __future__ import annotations

import gc
import threading
import weakref
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.services.monitoring import recording
from drivebench.web.app import create_app
from tests.conftest import wait_for_value
from tests.web.monitor_plant import PLANT, SESSION_ID, write_plant


@pytest.fixture
def api(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    monkeypatch.setattr(recording, "recordings_dir", lambda: tmp_path / "recordings")
    with TestClient(create_app()) as test_client:
        yield test_client


def test_closing_a_session_stops_its_recording_and_lets_the_session_go(api: TestClient, channel: str,
                                                                       tmp_path: Path) -> None:
    opened = api.post("/api/sessions", json={"bus": f"virtual:{channel}@500000", "name": "Recorded"})
    assert opened.status_code == 201
    session_id = opened.json()["id"]
    started = api.post(f"/api/sessions/{session_id}/monitor/recordings", json={"format": "asc"})
    assert started.status_code == 201
    path = tmp_path / "recordings" / started.json()["name"]
    with can.Bus(interface="virtual", channel=channel) as other:  # another device on the bus
        other.send(can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False))
        wait_for_value(lambda: api.get(f"/api/sessions/{session_id}/monitor").json()["totals"]["frames"] >= 1
                       or None, 15, "the frame counted")
    session = weakref.ref(api.app.state.drivebench.manager.get(session_id))

    assert api.delete(f"/api/sessions/{session_id}").status_code == 204

    assert not [thread for thread in threading.enumerate() if thread.name == f"recorder-{path.name}"]
    assert "End TriggerBlock" in path.read_text(), "the ASC writer finished the file"
    assert len(list(can.ASCReader(str(path)))) == 1
    gc.collect()
    assert session() is None, "nothing holds the closed session"


def test_a_reopened_session_starts_its_counter_history_afresh(tmp_path: Path, channel: str) -> None:
    app = create_app(plant_file=write_plant(tmp_path), plant_bus=f"virtual:{channel}@500000", latency="0ms")
    counters = f"/api/sessions/{SESSION_ID}/monitor/device-counters/5"
    with TestClient(app) as api:
        first = api.get(counters)
        assert first.status_code == 200, first.text
        assert first.json()["previous_time"] is None
        assert api.get(counters).json()["previous_time"] is not None  # the increases since the read before
        assert api.delete(f"/api/sessions/{SESSION_ID}").status_code == 204

        again = api.post("/api/sessions", json={"bus": f"virtual:{channel}@500000", "name": PLANT["name"]})
        assert again.status_code == 201 and again.json()["id"] == SESSION_ID
        added = api.post(f"/api/sessions/{SESSION_ID}/nodes", json={"node_id": 5,
                                                                    "profile_id": "lenze-8400-motec-canopen"})
        assert added.status_code == 201, added.text
        fresh = api.get(counters).json()
        assert fresh["previous_time"] is None, "the closed session's reads are gone with it"
        assert {row["device_increase"] for row in fresh["rows"]} == {None}
