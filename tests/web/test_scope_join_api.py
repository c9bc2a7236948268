"""Issue 31, the two halves joined, over the real HTTP API and websocket on the demo plant: a recording of the
CiA 402 servo (node 7) at 1 ms is sampled by PDO (the start asks for the confirmation of the SYNC and NMT start);
its samples during a profile-position move are the TPDO frames a second python-can bus sees on the plant's virtual
channel; while it holds the node, a second engineer's write to the node is refused in words (the owner's own writes
pass) and a viewer watches it live."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.services.scope import restore_record, runs
from drivebench.services.scope.joined import JoinedScopeSource
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, frames_in_bus_order, fresh_channel, wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline (a loaded clean-clone
# run quick-stopped node 7 between its enable and the move, the keep-alive thread's posts queued behind the start)

AXIS = 7
API = "/api/sessions/demo-plant"
CONTROL = f"{API}/nodes/{AXIS}/control"
TARGET = 720
BODY = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x606C"}], "period_ms": 1,
        "length_s": 100.0, "trigger": {"mode": "free"}, "name": "move at 1 ms"}


def _run(client: TestClient) -> runs.ScopeRun:
    return runs.current(client.app.state.drivebench.manager.get("demo-plant"))  # type: ignore[attr-defined]


def _enable(client: TestClient, headers: dict[str, str] | None = None) -> None:
    assert wait_until(lambda: client.get(CONTROL, headers=headers).json()["state"] == "switch_on_disabled", 15)
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{CONTROL}/commands/{command}", headers=headers).status_code == 200
    enabled = confirmed(client, "POST", f"{CONTROL}/commands/enable_operation", json={}, headers=headers)
    assert enabled.status_code == 200 and enabled.json()["enabled"], enabled.text


@contextlib.contextmanager
def _kept_alive(client: TestClient) -> Iterator[None]:
    """The keep-alive a control panel sends, every 0.5 s while the block runs: the node is armed from the enable on,
    and a start of the recording that takes over 2 s on a loaded machine let it lapse (CI: quick stop mid-move)."""
    done = threading.Event()

    def beat() -> None:
        while not done.wait(0.5):
            client.post(f"{API}/keepalive")
    beating = threading.Thread(target=beat, name="test-keepalive", daemon=True)
    beating.start()
    try:
        yield
    finally:
        done.set()
        beating.join(timeout=10)


def _position(client: TestClient) -> float:
    client.post(f"{API}/keepalive")
    return float(client.get(f"{API}/nodes/{AXIS}/parameters/0x6064").json()["value"])


def test_a_1_ms_recording_of_node_7_during_a_move_equals_the_tpdo_frames_on_the_bus(app_db_url: str) -> None:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client, can.Bus(interface="virtual", channel=channel) as wire, _kept_alive(client):
        _enable(client)
        client.post(f"{API}/keepalive")
        started = confirmed(client, "POST", f"{API}/scope/run", json=BODY)
        assert started.status_code == 201, started.text
        status = started.json()
        assert status["source"] == "pdo" and status["parts"][0]["nodes"] == [AXIS], status
        run = _run(client)
        source = run.source
        assert isinstance(source, JoinedScopeSource) and source.poll is None
        cob_id = source.pdo.plan.tpdos[0].cob_id
        moved = confirmed(client, "POST", f"{CONTROL}/move", json={"target": TARGET})
        assert moved.status_code == 200, moved.text
        assert wait_until(lambda: _position(client) == TARGET, 60), _position(client)
        time.sleep(0.2)
        stopped = client.post(f"{API}/scope/run/stop").json()
        assert stopped["state"] == "stopped" and stopped["recording_id"], stopped
        assert any("restored and read back as before" in text for text in stopped["restored"]), stopped["restored"]
        stored = client.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
        on_wire = frames_in_bus_order(wire)  # by send stamps: see there
    late, extra = source.pdo.late, source.pdo.extra
    syncs = -1
    want = []  # node 7's TPDO frames in bus order, each with the newest SYNC's number before it
    for msg in on_wire:
        if msg.arbitration_id == 0x080:
            syncs += 1
        elif msg.arbitration_id == cob_id and syncs >= 0:
            data = bytes(msg.data)
            want.append((syncs, tuple(info.value(int.from_bytes(data[at:at + 4], "little", signed=True))
                                      for info, at in zip(run.infos, (0, 4), strict=True))))
    assert stored["source"] == "pdo" and stored["period_s"] >= 0.00099, "the mean SYNC period reached"
    assert stored["samples"] == list(range(len(stored["samples"]))), "one sample per SYNC from the first"
    assert len(stored["samples"]) <= syncs + 1, "a sample per SYNC on the bus (the ones after Stop not kept)"
    got = [(n, (position, velocity)) for n, position, velocity in zip(stored["samples"], *stored["values"],
                                                                      strict=True) if position is not None]
    assert len(got) <= len(want)
    if late + extra:  # a loaded machine stalled the simulated drive longer than a sample waits: still the frames
        at = 0
        for _n, values in got:
            while want[at][1] != values:
                at += 1  # IndexError: a sample that is no TPDO frame of the bus
            at += 1
    else:
        assert [values for _n, values in got] == [values for _n, values in want[:len(got)]], "each is its TPDO"
        assert all(n <= bus_n for (n, _v), (bus_n, _w) in zip(got, want, strict=False)), "no answer before its SYNC"
        assert [n for n, _v in got] == list(range(got[0][0], got[0][0] + len(got))), "no SYNC without its sample"
    positions = [values[0] for _n, values in got]
    assert min(positions) < TARGET + 10 and max(positions) > TARGET + 1000, "it moved from 1908 ° to 720 °"
    assert any(values[1] for _n, values in got), "at a velocity"


# --- a second engineer ------------------------------------------------------------------------------------------
@pytest.fixture
def users(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, dict[str, str]]]:
    url = f"sqlite:///{tmp_path / 'scope.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(url)
    roles = {"root": Role.ADMIN, "eve": Role.ENGINEER, "fred": Role.ENGINEER, "vera": Role.VIEWER}
    for name, role in roles.items():
        accounts.create_user(name, f"{name} password", role)
    yield {name: {"Authorization": f"Bearer {accounts.issue_token(name, 'test', role).secret}"}
           for name, role in roles.items()}
    database.dispose(url)


def test_a_second_engineer_is_refused_in_words_while_a_pdo_recording_holds_the_node(
        users: dict[str, dict[str, str]]) -> None:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    eve, fred, vera = users["eve"], users["fred"], users["vera"]
    body = {**BODY, "period_ms": 5}
    with TestClient(app) as client:
        started = confirmed(client, "POST", f"{API}/scope/run", json=body, headers=eve)
        assert started.status_code == 201 and started.json()["source"] == "pdo", started.text
        refused = client.put(f"{API}/nodes/{AXIS}/parameters/0x2100", json={"value": 1}, headers=fred)
        assert refused.status_code == 409 and refused.headers["content-type"] == "application/problem+json"
        assert "eve" in refused.json()["detail"], refused.json()
        second = confirmed(client, "POST", f"{API}/scope/run", json=body, headers=fred)
        assert second.status_code == 409 and "eve is recording on this session already" in second.json()["detail"]
        own = client.put(f"{API}/nodes/{AXIS}/parameters/0x2100", json={"value": 1}, headers=eve)
        assert own.status_code == 200, own.text  # the lease is shared with the owner's own tuning writes
        rows: list[list[Any]] = []
        with client.websocket_connect("/ws/sessions/demo-plant/scope", headers=vera) as socket:
            while sum(row[2] is not None for row in rows) < 10:
                message = socket.receive_json()
                if message["type"] == "rows":
                    rows += message["rows"]
        watched = client.get(f"{API}/scope/run", headers=vera).json()
        assert watched["state"] == "recording", "a viewer who leaves ends nothing"
        stopped = client.post(f"{API}/scope/run/stop", headers=eve).json()
        assert stopped["state"] == "stopped"
        assert any("read back as before" in text for text in stopped["restored"]), stopped["restored"]


def test_the_server_stopping_restores_a_pdo_recording_before_it_closes_the_bus(app_db_url: str) -> None:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        started = confirmed(client, "POST", f"{API}/scope/run", json={**BODY, "period_ms": 5, "name": "cut short"})
        assert started.status_code == 201 and started.json()["source"] == "pdo", started.text
        assert len(restore_record.leftovers(app_db_url)) == 1, "the restore record is written before any change"
        run = _run(client)
        assert wait_until(lambda: len(run.live) > 10, 30)
    assert run.state == "stopped" and run.recording_id, run.status()
    assert any("read back as before" in text for text in run.restored), run.restored
    assert restore_record.leftovers(app_db_url) == [], "restored and read back: nothing left for the next start"
