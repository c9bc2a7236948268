"""Diagnostics through the real app: EMCY history with the manual's texts, heartbeat loss, heartbeat set-up,
the report, and the read-only guarantee of remote-diagnostics share links."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import fresh_channel, wait_for_value

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)

SESSION = "diagnostics-plant"


@pytest.fixture
def app_client(tmp_path: Path) -> Iterator[TestClient]:
    """Two Lenze drives with a 100 ms heartbeat on a fresh virtual bus."""
    plant_file = tmp_path / "plant.json"
    plant_file.write_text(json.dumps({"name": "Diagnostics plant", "bus": "virtual:x@500000", "nodes": [
        {"node_id": 5, "profile": "lenze-8400-motec-canopen", "heartbeat_ms": 100},
        {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib", "heartbeat_ms": 100}]}))
    app = create_app(plant_file=plant_file, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def plant_of(client: TestClient) -> Plant:
    plants: dict[str, Plant] = client.app.state.drivebench.plants  # type: ignore[attr-defined]
    return plants[SESSION]


def wait_for(check: Callable[[], Any], timeout_s: float = 5.0, what: str = "condition") -> Any:
    return wait_for_value(check, timeout_s, what)


def node_health(client: TestClient, node_id: int) -> dict[str, object]:
    sessions = client.get("/api/health/nodes").json()
    session = next(s for s in sessions if s["session_id"] == SESSION)
    node: dict[str, object] = next(n for n in session["nodes"] if n["node_id"] == node_id)
    return node


def test_emcy_history_is_decoded_with_the_manuals_texts(app_client: TestClient) -> None:
    drive = plant_of(app_client).nodes[5]
    drive.raise_emcy(0x3100, register=0x05)
    history = wait_for(lambda: app_client.get(f"/api/sessions/{SESSION}/nodes/5/emcy").json())
    assert isinstance(history, list)
    newest = history[0]
    assert newest["code"] == "0x3100"
    assert newest["vendor_text"].startswith("Supply voltage of standard device")
    assert newest["class_text"] == "Mains voltage"  # CiA 301: 0x31xx
    assert newest["error_register"] == "0x05"
    assert any("voltage" in bit.lower() for bit in newest["register_bits"])
    assert node_health(app_client, 5)["active_emcy"]["code"] == "0x3100"  # type: ignore[index]
    drive.clear_emcy()
    wait_for(lambda: node_health(app_client, 5)["active_emcy"] is None)
    assert [e["code"] for e in app_client.get(f"/api/sessions/{SESSION}/nodes/5/emcy").json()][:2] == \
        ["0x0000", "0x3100"]


def test_heartbeat_loss_is_detected_and_recovers(app_client: TestClient) -> None:
    wait_for(lambda: node_health(app_client, 12)["heartbeat_period_ms"])
    assert node_health(app_client, 12)["heartbeat_lost"] is False
    drive = plant_of(app_client).nodes[12]
    drive.power_off()
    wait_for(lambda: node_health(app_client, 12)["heartbeat_lost"])
    assert node_health(app_client, 5)["heartbeat_lost"] is False, "the other node is not affected"
    drive.power_on()
    wait_for(lambda: not node_health(app_client, 12)["heartbeat_lost"])
    assert node_health(app_client, 12)["bootups"] >= 1  # type: ignore[operator]


def test_heartbeat_consumer_setup_is_written_and_verified(app_client: TestClient) -> None:
    """8400 motec commissioning example: node 5 consumes node 12's heartbeat (consumer time > producer time)."""
    base = f"/api/sessions/{SESSION}/nodes/5/heartbeat"
    wait_for(lambda: node_health(app_client, 12)["heartbeat_period_ms"])
    setup = app_client.get(base).json()
    assert setup["producer_time_ms"] == 100
    assert len(setup["consumers"]) >= 1
    written = app_client.put(f"{base}/consumers/1", json={"producer_id": 12, "time_ms": 250})
    assert written.status_code == 200, written.text
    assert written.json()["consumers"][0] == {"slot": 1, "producer_id": 12, "time_ms": 250}
    assert plant_of(app_client).nodes[5].store.read(0x1016, 1) == ((12 << 16) | 250).to_bytes(4, "little")

    too_short = app_client.put(f"{base}/consumers/1", json={"producer_id": 12, "time_ms": 50})
    assert too_short.status_code == 422
    assert "longer than node 12's heartbeat producer time" in too_short.json()["detail"]
    missing = app_client.put(f"{base}/consumers/9", json={"producer_id": 12, "time_ms": 250})
    assert missing.status_code == 422 and "entry 9 does not exist" in missing.json()["detail"]

    producer = app_client.put(f"{base}/producer", json={"time_ms": 200})
    assert producer.json()["producer_time_ms"] == 200


def test_report_lists_nodes_and_emergencies(app_client: TestClient) -> None:
    plant_of(app_client).nodes[5].raise_emcy(0x3100)
    wait_for(lambda: app_client.get(f"/api/sessions/{SESSION}/nodes/5/emcy").json())
    response = app_client.get(f"/api/sessions/{SESSION}/diagnostics/report")
    assert response.status_code == 200
    assert "attachment" in response.headers["content-disposition"]
    assert "Supply voltage of standard device" in response.text
    assert "8400" in response.text and "Node 12" in response.text


def _writing_operations(client: TestClient) -> list[tuple[str, str]]:
    spec = client.get("/openapi.json").json()
    operations = []
    for path, methods in spec["paths"].items():
        for method in methods:
            if method.upper() not in {"GET", "HEAD", "OPTIONS"}:
                concrete = (path.replace("{session_id}", SESSION).replace("{node_id}", "5")
                            .replace("{slot}", "1").replace("{token}", "x").replace("{ref}", "C00088"))
                operations.append((method.upper(), concrete.replace("{", "").replace("}", "")))
    return operations


def test_a_share_link_can_read_but_never_write(app_client: TestClient) -> None:
    link = app_client.post("/api/share-links", json={"ttl_minutes": 5, "label": "service"}).json()
    assert link["url"].endswith(f"/remote/{link['token']}")
    viewer = {"Authorization": f"Bearer {link['token']}"}

    health = app_client.get("/api/health/nodes", headers=viewer)
    assert health.status_code == 200 and health.json()[0]["nodes"]
    operations = _writing_operations(app_client)
    assert len(operations) >= 8, operations
    for method, path in operations:
        response = app_client.request(method, path, headers=viewer, json={})
        assert response.status_code == 403, (method, path, response.status_code)
        assert "read-only" in response.json()["detail"]
    # The same requests without the token are not refused for that reason.
    start = {"command": "start", "confirm": "all", **NO_BROWSER}
    assert confirmed(app_client, "POST", f"/api/sessions/{SESSION}/nmt", json=start).status_code < 300
    assert app_client.get("/api/share-links", headers=viewer).status_code == 403

    page = app_client.get(f"/remote/{link['token']}")
    assert page.status_code == 200 and "read-only view" in page.text
    assert app_client.cookies.get("drivebench_viewer") == link["token"]
    assert app_client.post(f"/api/sessions/{SESSION}/nmt", json={"command": "stop"}).status_code == 403
    app_client.cookies.clear()

    assert app_client.delete(f"/api/share-links/{link['token']}").status_code == 204
    revoked = app_client.get("/api/health/nodes", headers=viewer)
    assert revoked.status_code == 401 and "not valid" in revoked.json()["detail"]


def test_remote_websocket_streams_health_and_refuses_bad_tokens(app_client: TestClient) -> None:
    token = app_client.post("/api/share-links", json={"ttl_minutes": 5}).json()["token"]
    with app_client.websocket_connect(f"/ws/remote/{token}") as ws:
        html = ws.receive_text()
    assert 'id="remote-health" hx-swap-oob="true"' in html
    assert "8400" in html
    with pytest.raises(Exception), app_client.websocket_connect("/ws/remote/dbv_wrong") as ws:  # noqa: B017
        ws.receive_text()


def test_node_guarding_answers_toggle_and_detects_loss(app_client: TestClient) -> None:
    """EMF2178IB supports node guarding (I-100C guard time, I-100D life time factor)."""
    base = f"/api/sessions/{SESSION}/nodes/12/guarding"
    started = app_client.put(base, json={"guard_time_ms": 50, "life_time_factor": 3})
    assert started.status_code == 200, started.text
    drive = plant_of(app_client).nodes[12]
    assert drive.store.read(0x100C, 0) == (50).to_bytes(2, "little")
    assert drive.store.read(0x100D, 0) == bytes([3])
    guard = wait_for(lambda: (g := node_health(app_client, 12)["guarding"]) and g["answers"] >= 4 and g)
    assert isinstance(guard, dict)
    assert guard["toggle_errors"] == 0 and guard["lost"] is False
    assert guard["state"] == "Pre-operational"

    drive.power_off()
    wait_for(lambda: node_health(app_client, 12)["guarding"]["lost"])  # type: ignore[index]
    assert node_health(app_client, 12)["nmt_state"] == "Node guarding lost"
    drive.power_on()
    wait_for(lambda: not node_health(app_client, 12)["guarding"]["lost"])  # type: ignore[index]

    refused = app_client.put(f"/api/sessions/{SESSION}/nodes/5/guarding", json={"guard_time_ms": 50})
    assert refused.status_code == 422 and "does not support node guarding" in refused.json()["detail"]
    stopped = app_client.put(base, json={"guard_time_ms": 0, "life_time_factor": 3})
    assert stopped.json()["guard_time_ms"] == 0
    assert node_health(app_client, 12)["guarding"] is None
