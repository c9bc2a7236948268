"""Drive control API on the demo plant: status with named bits, transitions with confirmation, setpoint, modes,
commissioning runs, problem+json errors, and the websocket keep-alive: disconnect -> quick stop."""

from __future__ import annotations

import time
from typing import Any

from fastapi.testclient import TestClient

BASE = "/api/sessions/demo-plant/nodes/{node}/control"
MM, VECTOR = 3, 12


def _url(node: int, tail: str = "") -> str:
    return BASE.format(node=node) + tail


def _until(client: TestClient, node: int, state: str, timeout_s: float = 8.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while (status := client.get(_url(node)).json())["state"] != state:
        assert time.monotonic() < deadline, f"node {node} stays in {status['state_label']}"
        time.sleep(0.05)
    return status


def _can_control(client: TestClient) -> None:
    for ref in ("P0700", "P1000"):
        response = client.put(f"/api/sessions/demo-plant/nodes/{MM}/parameters/{ref}", json={"value": "6"})
        assert response.status_code == 200, response.text


def test_status_names_every_bit_as_the_manual(client: TestClient) -> None:
    status = _until(client, MM, "switch_on_disabled")
    assert status["family"] == "cia402" and status["status_ref"] == "0x6041"
    assert [bit["name"] for bit in status["status_bits"]][:7] == [
        "Ready to switch on", "Switched on", "Operation enabled", "Fault", "Voltage enabled (MM: OFF2)",
        "Quick stop (0 = active)", "Switch on disabled"]
    assert status["control_bits"][7]["name"] == "Fault reset (fault acknowledge)"
    assert {state["key"] for state in status["states"]} >= {"switch_on_disabled", "operation_enabled", "fault"}
    assert status["modes"] == {"2": "Velocity mode", "4": "Profile torque mode"} and status["mode"] == 2
    lenze = client.get(_url(VECTOR)).json()
    assert lenze["family"] == "emf2178ib" and lenze["status_bits"][7]["name"] == "Controller inhibit (DCTRL1-CINH)"


def test_first_run_needs_confirmation_and_goes_back(client: TestClient) -> None:
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    assert client.post(_url(MM, "/commands/shutdown")).json()["state"] == "ready"
    assert client.post(_url(MM, "/commands/switch_on")).json()["state"] == "switched_on"
    refused = client.post(_url(MM, "/commands/enable_operation"))
    assert refused.status_code == 409 and refused.headers["content-type"] == "application/problem+json"
    assert "confirm" in refused.json()["detail"]
    enabled = client.post(_url(MM, "/commands/enable_operation"), json={"confirm": True}).json()
    assert enabled["state"] == "operation_enabled" and enabled["armed"]
    assert client.post(_url(MM, "/keepalive")).json() == {"armed": True}  # the 2 s keep-alive deadline restarts
    assert client.put(_url(MM, "/setpoint"), json={"value": 200}).status_code == 409
    assert client.put(_url(MM, "/setpoint"), json={"value": 9000, "confirm": True}).status_code == 422
    assert client.put(_url(MM, "/setpoint"), json={"value": 200, "confirm": True}).json()["control_word"] == 0x7F
    assert client.post(_url(MM, "/keepalive")).json() == {"armed": True}
    back = client.post(_url(MM, "/commands/shutdown")).json()
    assert back["state"] == "ready" and not back["armed"]
    assert client.post(_url(MM, "/keepalive")).json() == {"armed": False}
    assert client.post(_url(MM, "/commands/nonsense")).status_code == 422


def test_disconnect_sends_quick_stop(client: TestClient) -> None:
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    client.post(_url(MM, "/commands/shutdown"))
    with client.websocket_connect(f"/ws/sessions/demo-plant/nodes/{MM}/control") as socket:
        client.post(_url(MM, "/commands/enable_operation"), json={"confirm": True})
        message = socket.receive_json()
        while message["status"]["state"] != "operation_enabled":
            socket.send_json({"cmd": "keepalive"})
            message = socket.receive_json()
        assert message["type"] == "status" and message["actuals"][0]["label"] == "Speed"
        socket.send_json({"cmd": "keepalive"})
    status = _until(client, MM, "switch_on_disabled")  # quick stop active, then stopped (transition 12)
    assert status["last_trip"] and "disconnected" in status["last_trip"] and not status["armed"]


def test_modes_of_operation(client: TestClient) -> None:
    refused = client.put(_url(MM, "/mode"), json={"mode": 4})
    assert refused.status_code == 409 and "P1501" in refused.json()["detail"]
    client.put(f"/api/sessions/demo-plant/nodes/{MM}/parameters/P1501", json={"value": str(0x082B000C)})
    status = client.put(_url(MM, "/mode"), json={"mode": 4}).json()
    assert status["mode"] == 4 and status["setpoint_unit"] == "‰"
    assert client.put(_url(MM, "/mode"), json={"mode": 3}).status_code == 422
    assert client.put(_url(VECTOR, "/mode"), json={"mode": 2}).status_code == 422


def test_commissioning_run_over_the_api(client: TestClient) -> None:
    sequences = client.get(_url(VECTOR, "/sequences")).json()
    assert [seq["key"] for seq in sequences] == ["emf-8200"]
    run = client.post(_url(VECTOR, "/sequences/emf-8200/runs")).json()
    while not run["finished"]:
        step = run["steps"][run["position"]]
        response = client.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={"confirm": step["moves"]})
        assert response.status_code == 200, response.text
        run = response.json()
        client.post(_url(VECTOR, "/keepalive"))
    assert run["failed"] is None and all(result["ok"] for result in run["results"])
    assert run["results"][1]["telegrams"][0] == {"direction": "T", "cob_id": "0x60C",
                                                 "data": "23 FE 5F 00 30 75 00 00", "t": run["results"][1][
                                                     "telegrams"][0]["t"]}
    assert client.get(_url(VECTOR, "/runs/nope")).status_code == 404


def test_jog_runs_only_when_enabled_and_stops_with_zero(client: TestClient) -> None:
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    refused = client.post(_url(MM, "/jog"), json={"direction": 1, "confirm": True})
    assert refused.status_code == 409 and "operation enabled" in refused.json()["detail"]
    client.post(_url(MM, "/commands/shutdown"))
    client.post(_url(MM, "/commands/enable_operation"), json={"confirm": True})
    client.post(_url(MM, "/keepalive"))
    assert client.post(_url(MM, "/jog"), json={"direction": 1}).status_code == 409  # not confirmed
    assert client.post(_url(MM, "/jog"), json={"direction": -1, "confirm": True}).status_code == 200
    target = client.get(f"/api/sessions/demo-plant/nodes/{MM}/parameters/0x6042").json()
    assert target["value"] == -150  # 10 % of 0x6046.2 = 1500 rpm
    client.post(_url(MM, "/jog"), json={"direction": 0})
    assert client.get(f"/api/sessions/demo-plant/nodes/{MM}/parameters/0x6042").json()["value"] == 0
    assert client.post(_url(MM, "/jog"), json={"direction": 2}).status_code == 422
