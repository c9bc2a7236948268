"""Line addressing through the real HTTP API on the new-line plant (four devices without node ID on the real
python-can virtual bus): fastscan, assign with boot-up, the 428 of the steps that reach every device, the refusal
while a node is enabled or armed, the audit rows."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import can
import canopen
import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.services.users import audit
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel

NEW_LINE = REPO_ROOT / "plants" / "new-line.json"
LSS = "/api/sessions/new-line/lss"


@pytest.fixture
def line_api(app_db_url: str) -> Iterator[TestClient]:
    app = create_app(plant_file=NEW_LINE, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def test_fastscan_needs_the_confirmation_naming_every_device(line_api: TestClient) -> None:
    answer = line_api.post(f"{LSS}/fastscan", json={})
    assert answer.status_code == 428
    problem = answer.json()
    assert problem["confirm_node"] == "all"
    assert problem["confirm_values"]["reaches"] == "all nodes on this bus"
    assert problem["confirm_values"]["then"] == "switch state global (waiting)"
    wrong = line_api.post(f"{LSS}/fastscan", json={"confirm": "all", "confirm_values": {"LSS": "fastscan"}})
    assert wrong.status_code == 428
    for path, body in (("switch-global", {}), ("activate-bit-timing", {"bitrate": 250000}),
                       ("reset-communication", {})):
        refused = line_api.post(f"{LSS}/{path}", json=body)
        assert refused.status_code == 428, path
        assert refused.json()["confirm_node"] == "all"


def test_fastscan_finds_the_four_devices_and_one_is_addressed(line_api: TestClient) -> None:
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    assert found.status_code == 200, found.text
    devices = found.json()["devices"]
    assert sorted(int(device["serial"], 16) for device in devices) == [1001, 2002, 3003, 4004]
    assert found.json()["frames"] > 4 * 33
    pump = next(device for device in devices if int(device["serial"], 16) == 3003)
    assert pump["device"].startswith("MICROMASTER 420/430/440")
    body = {key: pump[key] for key in ("vendor", "product", "revision", "serial")} | {"node_id": 20}
    steps = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert steps.status_code == 200, steps.text
    texts = [step["text"] for step in steps.json()]
    assert all(step["ok"] for step in steps.json()), texts
    assert "node 20 booted (boot-up telegram)" in texts
    nodes = line_api.get("/api/sessions/new-line/nodes").json()
    assert [node["node_id"] for node in nodes] == [20]
    left = line_api.get(LSS).json()["devices"]
    assert len(left) == 3
    rows = audit.entries(session_id="new-line")
    assert any(row.new_value.startswith("assign: serial 0x00000BBB -> node ID 20") for row in rows)


def test_assign_to_a_device_that_is_not_there_says_so(line_api: TestClient) -> None:
    body = {"vendor": "0x1", "product": "0x2", "revision": "0x3", "serial": "0x4", "node_id": 21}
    answer = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert answer.status_code == 502
    assert "in LSS waiting state" in answer.json()["detail"]
    assert answer.headers["content-type"].startswith("application/problem+json")
    bad = confirmed(line_api, "POST", f"{LSS}/assign", json={**body, "serial": "zz"})
    assert bad.status_code == 422


def test_global_steps_are_refused_while_a_node_is_enabled_or_armed(app_db_url: str) -> None:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        started = confirmed(client, "POST", "/api/sessions/demo-plant/nodes/3/nmt",
                            json={"command": "start", "keepalive_s": 10})
        assert started.status_code == 200, started.text
        refused = client.post("/api/sessions/demo-plant/lss/fastscan", json={})
        assert refused.status_code == 409
        assert "refused while node 3 is enabled or armed" in refused.json()["detail"]
        client.post("/api/sessions/demo-plant/nodes/3/nmt", json={"command": "pre-operational"})
        # another master on the bus enables the servo: its status word says so
        network = canopen.Network(can.Bus(interface="virtual", channel=channel))
        network.connect()
        try:
            servo = network.add_node(7, canopen.ObjectDictionary())
            for word in (6, 7, 15):
                servo.sdo.download(0x6040, 0, word.to_bytes(2, "little"))
        finally:
            network.disconnect()
        refused = client.post("/api/sessions/demo-plant/lss/switch-global", json={})
        assert refused.status_code == 409
        assert "node 7 is enabled or armed" in refused.json()["detail"]


def test_a_device_with_a_node_id_moves_to_the_new_one(app_db_url: str, tmp_path: Path) -> None:
    plant = {"name": "Two", "nodes": [{"node_id": 5, "lss": True, "serial": 55, "profile": "generic-cia402-servo",
                                        "heartbeat_ms": 500}]}
    path = tmp_path / "two.json"
    path.write_text(json.dumps(plant), encoding="utf-8")
    app = create_app(plant_file=path, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        assert [node["node_id"] for node in client.get("/api/sessions/two/nodes").json()] == [5]
        body = {"vendor": 0, "product": "0x402001", "revision": "0x10000", "serial": 55, "node_id": 9}
        steps = confirmed(client, "POST", "/api/sessions/two/lss/assign", json=body)
        assert steps.status_code == 200, steps.text
        texts = [step["text"] for step in steps.json()]
        assert "device with serial 0x00000037 selected (its node ID: 5)" in texts
        assert "NMT reset communication sent to its old node ID 5" in texts
        assert "node 9 booted (boot-up telegram)" in texts
        assert [node["node_id"] for node in client.get("/api/sessions/two/nodes").json()] == [9]
