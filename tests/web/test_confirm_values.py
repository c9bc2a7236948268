"""Issue 27 item 1: a moving action is confirmed with the values it will send. Over the real HTTP API on the demo
plant: the 428 problem names the node (confirm_node) and the values the server built from the request
(confirm_values, units in the names); a confirmation repeating other values is refused with the request's own values
and nothing moves; repeating them sends exactly those (checked in the simulated drive)."""

from __future__ import annotations

import json
from typing import Any

import httpx
from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import wait_until

API = "/api/sessions/demo-plant/nodes"
SERVO, MM, MOTEC = 7, 3, 5
NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}


def _sim(client: TestClient, node: int) -> Any:
    return client.app.state.drivebench.plants["demo-plant"].nodes[node]  # type: ignore[attr-defined]


def _send(client: TestClient, method: str, url: str, body: dict[str, Any], form: bool,
          confirmation: dict[str, Any] | None = None) -> httpx.Response:
    if form:
        extra = {} if confirmation is None else {"confirm": str(confirmation["confirm"]),
                                                 "confirm_values": json.dumps(confirmation["confirm_values"])}
        return client.request(method, url, data={**body, **extra})
    return client.request(method, url, json={**body, **(confirmation or {})})


def _other(values: dict[str, Any]) -> dict[str, Any]:
    """The same names with one value changed (what a client confirmed before the user changed it)."""
    key = next(iter(values))
    value = values[key]
    changed = value + 1 if isinstance(value, (int, float)) and not isinstance(value, bool) else f"{value}0"
    return {**values, key: changed}


def _differ_then_match(client: TestClient, method: str, url: str, body: dict[str, Any], node: int | str, *,
                       form: bool = False) -> tuple[dict[str, Any], httpx.Response]:
    """The 428 names the node and the values; other values are refused with the request's own; the same pass."""
    asked = _send(client, method, url, body, form)
    assert asked.status_code == 428, asked.text
    assert asked.headers["content-type"] == "application/problem+json"
    problem = asked.json()
    assert problem["confirm_node"] == node and problem["confirm_values"], problem
    values: dict[str, Any] = problem["confirm_values"]
    for wrong in (_other(values), {}, None):
        again = _send(client, method, url, body, form, {"confirm": node, "confirm_values": wrong})
        assert again.status_code == 428, f"{wrong}: {again.text}"
        assert again.json()["confirm_values"] == values, "the refusal names what this request would send"
    assert "changed" in _send(client, method, url, body, form,
                              {"confirm": node, "confirm_values": _other(values)}).json()["detail"]
    done = _send(client, method, url, body, form, {"confirm": node, "confirm_values": values})
    assert done.status_code < 300, done.text
    return values, done


def _enabled(client: TestClient, node: int) -> None:
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{API}/{node}/control/commands/{command}").status_code == 200
    enabled = confirmed(client, "POST", f"{API}/{node}/control/commands/enable_operation")
    assert enabled.status_code == 200 and enabled.json()["state"] == "operation_enabled", enabled.text


def test_a_jog_is_confirmed_with_the_speed_it_sends(client: TestClient) -> None:
    sim = _sim(client, SERVO)
    _enabled(client, SERVO)
    jog = f"{API}/{SERVO}/control/jog"
    shown = client.post(jog, json={"direction": 1, "speed": 300}).json()["confirm_values"]
    asked = client.post(jog, json={"direction": 1, "speed": 2500})
    assert asked.status_code == 428
    values = asked.json()["confirm_values"]
    speed = [key for key in values if key.startswith("0x60FF")]
    assert speed and speed[0].endswith("[rpm]") and values[speed[0]] == 2500, values
    assert values["0x6060 Modes of operation"] == 3
    # the case: the dialog showed 300 rpm, the request sends 2500: confirming 300 does not send 2500
    stale = client.post(jog, json={"direction": 1, "speed": 2500, "confirm": SERVO, "confirm_values": shown})
    assert stale.status_code == 428 and stale.json()["confirm_values"] == values
    assert sim.store.get(0x60FF, 0) == 0, "nothing was sent with the stale confirmation"
    by_header = client.post(jog, json={"direction": 1, "speed": 2500},
                            headers={"X-DriveBench-Confirm": str(SERVO),
                                     "X-DriveBench-Confirm-Values": json.dumps({**values, speed[0]: 2500.0})})
    assert by_header.status_code == 200, by_header.text  # numbers compare as numbers
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 2500)
    assert client.post(jog, json={"direction": 0}).status_code == 200  # release: no confirmation to stop
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 0)
    reverse, _done = _differ_then_match(client, "POST", jog, {"direction": -1, "speed": 1000}, SERVO)
    assert reverse[speed[0]] == -1000
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == -1000)
    client.post(jog, json={"direction": 0})


def test_setpoint_and_command_name_what_they_write(client: TestClient) -> None:
    sim = _sim(client, MM)
    for ref in ("P0700", "P1000"):
        sim.store.set_ref(ref, 6)
    assert client.post(f"{API}/{MM}/control/commands/shutdown").status_code == 200
    values, _done = _differ_then_match(client, "POST", f"{API}/{MM}/control/commands/enable_operation", {}, MM)
    word = [value for key, value in values.items() if key.startswith("0x6040 ")]
    assert values["command"] == "enable_operation" and word == ["0x000F"], values
    values, _done = _differ_then_match(client, "PUT", f"{API}/{MM}/control/setpoint", {"value": 200}, MM)
    assert list(values.values()) == [200] and next(iter(values)).endswith("[rpm]"), values
    assert wait_until(lambda: sim.store.get(0x6042, 0) == 200)
    client.post(f"{API}/{MM}/control/commands/quick_stop")


def test_a_parameter_write_and_a_batch_are_confirmed_with_their_values(client: TestClient) -> None:
    sim = _sim(client, MM)
    values, _done = _differ_then_match(client, "PUT", f"{API}/{MM}/parameters/P0700", {"value": 6, "verify": False},
                                       MM)
    assert list(values) == [key for key in values if key.startswith("P0700 ")] and 6 in values.values(), values
    assert sim.store.get_ref("P0700") == 6
    batch = {"items": [{"ref": "P1000", "value": 6}, {"ref": "0x6042", "value": 100}], "verify": False}
    values, done = _differ_then_match(client, "POST", f"{API}/{MM}/parameters:write", batch, MM)
    assert len(values) == 2 and done.json()["complete"], (values, done.text)
    assert sim.store.get_ref("P1000") == 6 and sim.store.get(0x6042, 0) == 100


def test_nmt_start_and_an_rpdo_are_confirmed_with_their_values(client: TestClient) -> None:
    sim = _sim(client, MM)
    values, _done = _differ_then_match(client, "POST", "/api/sessions/demo-plant/nmt",
                                       {"command": "start", **NO_BROWSER}, "all")
    assert values == {"NMT": "start", "nodes": [3, 5, 7, 12]}
    assert wait_until(lambda: sim.state.name == "OPERATIONAL")
    client.post("/api/sessions/demo-plant/nmt", json={"command": "pre-operational"})
    values, _done = _differ_then_match(client, "POST", f"{API}/{MM}/nmt", {"command": "start", **NO_BROWSER}, MM)
    assert values == {"NMT": "start"}
    assert client.put(f"{API}/{MM}/pdos/rpdo/5", json={"entries": [[0x6040, 0], [0x6042, 0]]}).status_code == 200
    client.get(f"/ui/sessions/demo-plant/nodes/{MM}/pdo")  # reads the mappings the sender packs by
    send = {"mode": "once", "v:0x6040": "6", "v:0x6042": "-750", "keepalive": "false", "reason": "test"}
    values, _done = _differ_then_match(client, "POST", f"/ui/sessions/demo-plant/nodes/{MM}/pdo/rpdo/5/send", send,
                                       MM, form=True)
    assert values == {"RPDO": 5, "0x6040": "6", "0x6042": "-750"}
    assert wait_until(lambda: sim.store.get(0x6042, 0) == -750)


def test_a_set_download_is_confirmed_with_the_moving_values_it_writes(demo_api: TestClient) -> None:
    """Node 12 (8200 vector): C0001, the setpoint source, can move the drive. (The 8400 motec's CAN input words
    C00866, used here before, are process data a set no longer holds: issue 28 item 1.)"""
    api, sets, fan = demo_api, "/api/parameter-sets", 12
    held = api.get(f"{API}/{fan}/parameters/C0001").json()["value"]
    target = 1 if held != 1 else 2
    job = api.post(f"{sets}/upload", json={"session_id": "demo-plant", "node_id": fan, "name": "Fan"}).json()
    assert wait_until(lambda: api.get(f"{sets}/jobs/{job['id']}").json()["state"] != "running", 30)
    set_id = api.get(f"{sets}/jobs/{job['id']}").json()["set_id"]
    assert api.patch(f"{sets}/{set_id}", json={"values": {"C0001": target}}).status_code == 200
    values, done = _differ_then_match(api, "POST", f"{sets}/{set_id}/download",
                                      {"session_id": "demo-plant", "node_id": fan}, fan)
    assert values and all(key.startswith("C0001 ") for key in values), values
    assert wait_until(lambda: api.get(f"{sets}/jobs/{done.json()['id']}").json()["state"] != "running", 30)
    assert api.get(f"{API}/{fan}/parameters/C0001").json()["value"] == target
