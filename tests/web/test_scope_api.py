"""Issue 31, the recording half, over the real HTTP API and websocket on the demo plant (SDO polling on the virtual
bus): the MICROMASTER (node 3) and the 8400 motec (node 5) ramp up together, a single capture triggers on node 3's
speed rising above 500 rpm with 20 % pre-trigger; the trigger sample is the first one above 500 after the
pre-trigger samples; the stored recording reads back and exports as CSV; a viewer watches live; only an engineer
starts a recording."""

from __future__ import annotations

import contextlib
import csv
import io
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.services.scope import channels, runs, store
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

API = "/api/sessions/demo-plant"
MM, MOTEC = 3, 5
SPEED_MM, SPEED_MOTEC = "0x6044", "C00868/2"
LENGTH, PRE = 40, 20


def _sim(client: TestClient, node: int) -> Any:
    return client.app.state.drivebench.plants["demo-plant"].nodes[node]  # type: ignore[attr-defined]


@contextlib.contextmanager
def _kept_alive(client: TestClient) -> Iterator[None]:
    """Keep-alives for both drives from a thread of their own, every 0.25 s: on a loaded machine the run-up's
    requests one after the other took longer than the guard's 2 s and it stopped node 3 mid-ramp (the capture then
    waited for a crossing that never came)."""
    stop = threading.Event()

    def beat() -> None:
        while not stop.wait(0.25):
            for node in (MM, MOTEC):
                client.post(f"{API}/nodes/{node}/control/keepalive")

    beating = threading.Thread(target=beat, daemon=True)
    beating.start()
    try:
        yield
    finally:
        stop.set()
        beating.join(10)


def _run_up(client: TestClient, node: int, rpm: int) -> None:
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{API}/nodes/{node}/control/commands/{command}").status_code == 200
    enabled = confirmed(client, "POST", f"{API}/nodes/{node}/control/commands/enable_operation")
    assert enabled.status_code == 200, enabled.text
    sent = confirmed(client, "PUT", f"{API}/nodes/{node}/control/setpoint", json={"value": rpm})
    assert sent.status_code == 200, sent.text


def _start_body(**trigger: Any) -> dict[str, Any]:
    return {"channels": [{"node": MM, "ref": SPEED_MM}, {"node": MOTEC, "ref": SPEED_MOTEC},
                         {"node": MM, "ref": "0x6041", "bit": 2}],
            "period_ms": 50, "length_samples": LENGTH, "name": "ramp",
            "trigger": {"mode": "single", "on": "level", "channel": 0, "edge": "rising", "level": 500,
                        "pre_percent": PRE, **trigger}}


def _record_ramp(client: TestClient) -> dict[str, Any]:
    for ref in ("P0700", "P1000"):  # the MICROMASTER takes commands and setpoint from CANopen
        _sim(client, MM).store.set_ref(ref, 6)
    started = confirmed(client, "POST", f"{API}/scope/run", json=_start_body())
    assert started.status_code == 201, started.text
    status = started.json()
    assert status["state"] == "armed" and status["source"] == "pdo" and status["trigger"]["pre"] == 8
    assert [c["unit"] for c in status["channels"]] == ["rpm", "rpm", None]
    assert "Node 5 is sampled by polling: it has no free TPDO" in " ".join(status["plan"]), status["plan"]
    assert [(p["kind"], p["nodes"]) for p in status["parts"]] == [("pdo", [MM]), ("sdo-poll", [MOTEC])]
    assert wait_until(lambda: _samples(client) >= 2 * PRE, 30)  # pre-trigger samples at standstill first
    with _kept_alive(client):
        _run_up(client, MM, 1200)
        _run_up(client, MOTEC, 1200)
        assert wait_until(lambda: client.get(f"{API}/scope/run").json()["state"] == "done", 60), client.get(
            f"{API}/scope/run").json()
    for node in (MM, MOTEC):
        client.post(f"{API}/nodes/{node}/control/commands/quick_stop")
    final: dict[str, Any] = client.get(f"{API}/scope/run").json()
    assert final["recording_id"] and final["period_s"] == pytest.approx(0.05, rel=0.2) and final["rate"] > 0
    return final


def test_a_single_capture_of_two_ramping_drives_triggers_at_the_first_sample_above_the_level(
        demo_api: TestClient) -> None:
    final = _record_ramp(demo_api)
    stored = demo_api.get(f"/api/scope/recordings/{final['recording_id']}").json()
    assert stored["count"] == LENGTH and stored["source"] == "pdo"
    position = stored["trigger"]["position"]
    assert position == round(LENGTH * PRE / 100) == 8
    speed = stored["values"][0]
    # a sample a stalled simulated drive did not answer in time is a gap (None), never a value above the level
    assert speed[position] > 500 and all(v is None or v <= 500 for v in speed[:position]), speed
    assert sum(v is not None for v in speed[:position]) >= position // 2, speed
    assert stored["samples"] == list(range(stored["samples"][0], stored["samples"][0] + LENGTH)), "no round lost"
    motec = stored["values"][1]
    assert all(v is not None for v in motec) and max(motec) > 100, f"the 8400 ramps on the same time base: {motec}"
    assert stored["nodes"]["5"]["profile_id"] == "lenze-8400-motec-canopen"
    assert [c["ref"] for c in stored["channels"]] == [SPEED_MM, SPEED_MOTEC, "0x6041"]

    exported = demo_api.get(f"/api/scope/recordings/{final['recording_id']}/export?format=csv")
    assert exported.status_code == 200 and exported.headers["content-type"].startswith("text/csv")
    rows = list(csv.reader(io.StringIO(exported.text)))
    assert rows[0][:2] == ["sample", "time_s"] and rows[0][2].endswith("[rpm]") and "0x6044" in rows[0][2]
    assert len(rows) == LENGTH + 1
    assert float(rows[1 + position][2]) == pytest.approx(speed[position])
    assert float(rows[position][2]) <= 500 < float(rows[1 + position][2])
    listed = demo_api.get("/api/scope/recordings").json()
    assert [r["id"] for r in listed] == [final["recording_id"]] and "samples" not in listed[0]
    as_json = demo_api.get(f"/api/scope/recordings/{final['recording_id']}/export?format=json").json()
    assert as_json["values"] == stored["values"]
    assert demo_api.delete(f"/api/scope/recordings/{final['recording_id']}").status_code == 204
    gone = demo_api.get(f"/api/scope/recordings/{final['recording_id']}")
    assert gone.status_code == 404 and "no scope recording" in gone.json()["detail"]


def test_a_viewer_watches_a_free_run_live_and_stop_keeps_it(demo_api: TestClient) -> None:
    with demo_api.websocket_connect("/ws/sessions/demo-plant/scope") as socket:
        assert socket.receive_json() == {"type": "state", "state": "none"}
        body = {**_start_body(mode="free"), "length_s": 100.0, "length_samples": None}
        started = confirmed(demo_api, "POST", f"{API}/scope/run", json=body)
        assert started.status_code == 201, started.text
        busy = demo_api.post(f"{API}/scope/run", json=body)
        assert busy.status_code == 409 and "stop that recording first" in busy.json()["detail"]
        rows: list[list[Any]] = []
        while sum(row[2] is not None for row in rows) < 5:  # a node the recording starts answers a SYNC later
            message = socket.receive_json()
            if message["type"] == "rows":
                rows += message["rows"]
        assert [len(row) for row in rows] == [5] * len(rows), "sample, time, three channels"
        assert next(row[2] for row in rows if row[2] is not None) == 0 and rows[-1][0] > rows[0][0]
        stopped = demo_api.post(f"{API}/scope/run/stop").json()
        assert stopped["state"] == "stopped" and stopped["recording_id"]
        while (message := socket.receive_json())["type"] != "state" or message["state"] != "stopped":
            pass
    stored = demo_api.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
    assert stored["count"] >= 5 and stored["trigger"]["position"] is None


@pytest.mark.parametrize(("change", "words"), [
    ({"channels": [{"node": MM, "ref": "P9999"}]}, "P9999"),
    ({"channels": [{"node": MM, "ref": SPEED_MM}] * 2}, "named twice"),
    ({"period_ms": 60_000}, "1 ms to 10 s"),
    ({"channels": [{"node": MM, "ref": "0x6041", "bit": 40}]}, "bits 0 to 15"),
    ({"length_s": 2.0}, "one of the two"),
])
def test_bad_settings_are_refused_in_words_and_nothing_starts(demo_api: TestClient, change: dict[str, Any],
                                                               words: str) -> None:
    refused = demo_api.post(f"{API}/scope/run", json={**_start_body(), **change})
    assert refused.status_code in (404, 422) and refused.headers["content-type"] == "application/problem+json"
    assert words in refused.json()["detail"], refused.json()
    assert demo_api.get(f"{API}/scope/run").status_code == 404


def test_channels_offer_the_mappable_objects_and_actual_values_by_name_code_or_index(demo_api: TestClient) -> None:
    motec = demo_api.get(f"{API}/scope/channels", params={"node": MOTEC, "q": "speed"}).json()
    assert [c["ref"] for c in motec] == [SPEED_MOTEC] and motec[0]["unit"] == "rpm"
    servo = {c["ref"] for c in demo_api.get(f"{API}/scope/channels", params={"node": 7}).json()}
    assert {"0x6064", "0x606C", "0x6077", "0x6078", "0x60F4", "0x6041"} <= servo
    assert [c["ref"] for c in demo_api.get(f"{API}/scope/channels", params={"node": 7, "q": "0x606c"}).json()] == [
        "0x606C"]


# --- roles ------------------------------------------------------------------------------------------------------
@pytest.fixture
def with_users(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, str]]:
    url = f"sqlite:///{tmp_path / 'scope.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(url)
    roles = {"root": Role.ADMIN, "eve": Role.ENGINEER, "vera": Role.VIEWER}  # an admin: everyone signs in
    for name, role in roles.items():
        accounts.create_user(name, f"{name} password", role)
    yield {name: accounts.issue_token(name, "test", role).secret for name, role in roles.items()}
    database.dispose(url)


def test_only_an_engineer_starts_a_recording_a_viewer_watches_it(with_users: dict[str, str]) -> None:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    viewer = {"Authorization": f"Bearer {with_users['vera']}"}
    engineer = {"Authorization": f"Bearer {with_users['eve']}"}
    body = {**_start_body(mode="free"), "length_s": 100.0, "length_samples": None}
    with TestClient(app) as client:
        refused = client.post(f"{API}/scope/run", json=body, headers=viewer)
        assert refused.status_code == 403
        assert "Starting and stopping scope recordings" in refused.json()["detail"], refused.json()
        assert client.get(f"{API}/scope/run", headers=viewer).status_code == 404
        started = confirmed(client, "POST", f"{API}/scope/run", json=body, headers=engineer)
        assert started.status_code == 201 and started.json()["user"] == "eve"
        with client.websocket_connect("/ws/sessions/demo-plant/scope", headers=viewer) as socket:
            assert wait_until(lambda: socket.receive_json()["type"] == "rows", 20)
        assert client.post(f"{API}/scope/run/stop", headers=viewer).status_code == 403
        stopped = client.post(f"{API}/scope/run/stop", headers=engineer).json()
        assert stopped["state"] == "stopped"
        recording = client.get(f"/api/scope/recordings/{stopped['recording_id']}", headers=viewer).json()
        assert recording["created_by"] == "eve" and not any(
            isinstance(v, float) and math.isnan(v) for column in recording["values"] for v in column)
        assert client.delete(f"/api/scope/recordings/{stopped['recording_id']}", headers=viewer).status_code == 403


def test_a_recording_running_when_the_server_stops_is_stored(app_db_url: str) -> None:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    body = {**_start_body(mode="free"), "length_s": 100.0, "length_samples": None, "name": "cut short"}
    with TestClient(app) as client:
        assert confirmed(client, "POST", f"{API}/scope/run", json=body).status_code == 201
        with client.websocket_connect("/ws/sessions/demo-plant/scope") as socket:
            assert wait_until(lambda: socket.receive_json()["type"] == "rows", 20)
    kept = [r for r in store.listing() if r["name"] == "cut short"]
    assert len(kept) == 1 and kept[0]["count"] >= 1


def test_an_emcy_of_the_named_node_on_the_bus_triggers_and_is_a_marker(app_db_url: str) -> None:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    body = {"channels": [{"node": MM, "ref": SPEED_MM}, {"node": MOTEC, "ref": SPEED_MOTEC}], "period_ms": 50,
            "length_samples": 10, "trigger": {"mode": "single", "on": "emcy", "node": MOTEC, "pre_percent": 50}}
    with TestClient(app) as client, can.Bus(interface="virtual", channel=channel) as wire:
        started = confirmed(client, "POST", f"{API}/scope/run", json=body)
        assert started.status_code == 201, started.text
        assert wait_until(lambda: _samples(client) >= 8, 30)  # the pre-trigger samples first
        wire.send(can.Message(arbitration_id=0x80 + 12, data=bytes([0x10, 0x23, 0x01, 0, 0, 0, 0, 0]),
                              is_extended_id=False))  # node 12: neither the trigger's node nor recorded
        time.sleep(0.5)
        assert client.get(f"{API}/scope/run").json()["state"] == "armed"
        wire.send(can.Message(arbitration_id=0x80 + MOTEC, data=bytes([0x10, 0x23, 0x01, 0, 0, 0, 0, 0]),
                              is_extended_id=False))
        assert wait_until(lambda: client.get(f"{API}/scope/run").json()["state"] == "done", 30)
        stored = client.get(f"/api/scope/recordings/{client.get(f'{API}/scope/run').json()['recording_id']}").json()
    assert stored["trigger"]["position"] == 5
    # the source's own markers (a SYNC pause on a busy machine) may be there too; node 12's EMCY is not
    events = [m for m in stored["markers"] if m["kind"] != "source"]
    assert [(m["node"], m["kind"], m["text"]) for m in events] == [(MOTEC, "emcy", "EMCY 2310h")], stored["markers"]
    marker_s, trigger_s = events[0]["time_s"], stored["trigger"]["time_s"]
    assert stored["times"][4] < marker_s <= trigger_s, "the trigger is the first sample at or after the EMCY"


def test_a_recorded_status_word_marks_each_drive_state_change(demo_api: TestClient) -> None:
    body = {"channels": [{"node": MOTEC, "ref": "C00868/1"}, {"node": MM, "ref": SPEED_MM}], "period_ms": 50,
            "length_s": 100.0, "trigger": {"mode": "free"}}
    assert confirmed(demo_api, "POST", f"{API}/scope/run", json=body).status_code == 201
    time.sleep(0.5)

    def states() -> list[tuple[int | None, str]]:
        return [(e.node, e.text) for e in _run_events(demo_api) if e.kind == "drive-state"]

    before = demo_api.get(f"{API}/nodes/{MOTEC}/control").json()["state"]
    assert before == "ready"
    shown = []
    for command in ("switch_on", "shutdown"):  # neither moves the drive: no confirmation
        assert demo_api.post(f"{API}/nodes/{MOTEC}/control/commands/{command}").status_code == 200
        client_state = demo_api.get(f"{API}/nodes/{MOTEC}/control").json()["state_label"]
        shown.append((MOTEC, client_state))
        assert wait_until(lambda: states() == shown, 20), (client_state, states())
    stopped = demo_api.post(f"{API}/scope/run/stop").json()
    stored = demo_api.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
    marked = [(m["node"], m["text"]) for m in stored["markers"] if m["kind"] == "drive-state"]
    assert marked == shown == [(MOTEC, "Switched on"), (MOTEC, "Ready to switch on")], stored["markers"]


def _samples(client: TestClient) -> int:
    """Samples the running recording has delivered so far (of the last 2,000 kept for late viewers)."""
    session = client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]
    return len(runs.current(session).live)


def _run_events(client: TestClient) -> list[Any]:
    session = client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]
    return list(runs.current(session).events)


def test_the_nmt_start_of_a_recording_is_a_marker_at_its_first_samples_on_slow_drives(app_db_url: str) -> None:
    """Session events (EMCY, NMT) go on the samples' time base: the NMT start the recording sends right after its
    first SYNC is marked where the node's heartbeat reported it, not later by the time the TPDO set-up of slow
    drives took (it was: ~1.5 s into a recording whose samples began at 0)."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="30ms")
    with TestClient(app) as client:
        body = {"channels": [{"node": MM, "ref": "0x6044"}], "period_ms": 10, "length_s": 100.0,
                "trigger": {"mode": "free"}}
        started = confirmed(client, "POST", f"{API}/scope/run", json=body)
        assert started.status_code == 201, started.text
        assert started.json()["source"] == "pdo", started.json()
        assert wait_until(lambda: any(e.kind == "nmt" and e.node == MM for e in _run_events(client)), 30)
        stopped = client.post(f"{API}/scope/run/stop").json()
        stored = client.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
    nmt = [m for m in stored["markers"] if m["kind"] == "nmt" and m["node"] == MM]
    assert nmt and "Operational" in nmt[0]["text"], stored["markers"]  # old: after the last sample, so not kept
    # seen in the node's next heartbeat after the start: within the samples, not the set-up's time later
    assert stored["times"][0] <= nmt[0]["time_s"] <= stored["times"][-1], (nmt[0], stored["times"][-1])


def test_the_control_tab_panel_channels_say_how_they_are_sampled(demo_api: TestClient) -> None:
    """Issue 31's open point: the panel's default channels of the MICROMASTER went to SDO polling with no reason
    shown. Now they are sampled by PDO (mapped in its mapping sequence), and the 8400 motec's plan says why it is
    polled: its TPDOs send the static port words, and two of its actual values no TPDO may carry."""
    session = demo_api.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]

    def panel_body(node: int) -> dict[str, Any]:
        return {"channels": [{"node": node, "ref": c.ref} for c in channels.panel_channels(session, node)],
                "period_ms": 20, "length_s": 10, "trigger": {"mode": "free"}, "name": f"panel {node}"}

    started = confirmed(demo_api, "POST", f"{API}/scope/run", json=panel_body(MM))
    assert started.status_code == 201, started.text
    status = started.json()
    assert [(p["kind"], p["nodes"]) for p in status["parts"]] == [("pdo", [MM])], status["plan"]
    assert status["plan"][0] == "Node 3: TPDO5 (COB-ID 0x283) carries 0x6041, 0x6077, 0x6044, synchronous every SYNC."
    assert wait_until(lambda: _samples(demo_api) >= 3 and all(
        v is not None for v in runs.current(session).live[-1][2:]), 30), "node 3 sends its TPDO5"
    stopped = demo_api.post(f"{API}/scope/run/stop").json()
    assert stopped["state"] == "stopped" and stopped["restored"], stopped

    started = demo_api.post(f"{API}/scope/run", json=panel_body(MOTEC))
    assert started.status_code == 201, started.text  # polling alone moves nothing: no confirmation
    status = started.json()
    assert status["source"] == "sdo-poll"
    assert status["plan"] == [
        "Node 5 is sampled by polling: it has no free TPDO: TPDO1 sends the device's static mapping (C00868/1, "
        "C00868/2, C00868/3, C00868/4); TPDO2 sends the device's static mapping (C00868/5, C00868/6, C00868/7, "
        "C00868/8).",
        "Node 5: C00054, C00053 polled: its profile does not list them as TPDO-mappable."]
    assert demo_api.post(f"{API}/scope/run/stop").status_code == 200
