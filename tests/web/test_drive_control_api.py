"""Drive control API on the demo plant: status with named bits, transitions with confirmation, setpoint, modes,
commissioning runs, problem+json errors, and the websocket keep-alive: disconnect -> quick stop."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from drivebench.device.profiles.scaling import to_raw
from drivebench.services.users.audit import LOCAL_USER
from tests.confirming import confirmed
from tests.conftest import wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

BASE = "/api/sessions/demo-plant/nodes/{node}/control"
MM, VECTOR = 3, 12


def _url(node: int, tail: str = "") -> str:
    return BASE.format(node=node) + tail


def _until(client: TestClient, node: int, state: str, timeout_s: float = 8.0) -> dict[str, Any]:
    status: dict[str, Any] = {}

    def reached() -> bool:
        status.update(client.get(_url(node)).json())
        return status["state"] == state
    assert wait_until(reached, timeout_s), f"node {node} stays in {status['state_label']}"
    return status


def _plant_set(client: TestClient, node: int, ref: str, value: int) -> None:
    """The plant as the test needs it (a command source set at the drive): writing these through the API is a
    write that can move the drive (confirmed and armed, see test_moving_writes), not what these tests are about."""
    store = client.app.state.drivebench.plants["demo-plant"].nodes[node].store  # type: ignore[attr-defined]
    store.set_ref(ref, to_raw(store.catalog.resolve(ref).entry, value))


def _can_control(client: TestClient) -> None:
    for ref in ("P0700", "P1000"):
        _plant_set(client, MM, ref, 6)


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
    assert refused.status_code == 428 and refused.headers["content-type"] == "application/problem+json"
    assert "confirm" in refused.json()["detail"] and "node 3" in refused.json()["detail"]
    bare = confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": True})
    assert bare.status_code == 428, "a bare true does not name the node"
    enabled = confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": MM}).json()
    assert enabled["state"] == "operation_enabled" and enabled["armed"]
    kept = client.post(_url(MM, "/keepalive")).json()  # the 2 s keep-alive deadline restarts
    assert kept["armed"] and kept["holder"].startswith(f"{LOCAL_USER} at testclient since ")  # the principal
    assert client.put(_url(MM, "/setpoint"), json={"value": 200}).status_code == 428
    assert confirmed(client, "PUT", _url(MM, "/setpoint"), json={"value": 9000, "confirm": MM}).status_code == 422
    assert confirmed(client, "PUT", _url(MM, "/setpoint"),
                     json={"value": 200, "confirm": MM}).json()["control_word"] == 0x7F
    assert client.post(_url(MM, "/keepalive")).json()["armed"]
    back = client.post(_url(MM, "/commands/shutdown")).json()
    assert back["state"] == "ready" and not back["armed"] and back["holder"] is None
    assert client.post(_url(MM, "/keepalive")).json() == {"armed": False, "holder": None}
    assert client.post(_url(MM, "/commands/nonsense")).status_code == 422


def _enabled_on_a_panel(client: TestClient, socket: Any) -> dict[str, Any]:
    """The MICROMASTER enabled while ``socket`` (its control panel) keeps it alive; the panel's last message."""
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    client.post(_url(MM, "/commands/shutdown"))
    confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": MM})
    message: dict[str, Any] = socket.receive_json()
    while message["status"]["state"] != "operation_enabled":
        socket.send_json({"cmd": "keepalive"})
        message = socket.receive_json()
    return message


def test_disconnect_sends_quick_stop(client: TestClient) -> None:
    with client.websocket_connect(f"/ws/sessions/demo-plant/nodes/{MM}/control") as socket:
        message = _enabled_on_a_panel(client, socket)
        assert message["type"] == "status" and message["actuals"][0]["label"] == "Speed"
        socket.send_json({"cmd": "keepalive"})
    status = _until(client, MM, "switch_on_disabled")  # quick stop active, then stopped (transition 12)
    assert status["last_trip"] and "disconnected" in status["last_trip"] and not status["armed"]


def test_a_quick_stop_whose_answer_is_lost_is_sent_again(client: TestClient) -> None:
    """The drive loses the guard's quick stop and the SDO retry of it (a busy bus): the guard sends it again rather
    than leave the drive enabled with 'Quick stop FAILED'."""
    with client.websocket_connect(f"/ws/sessions/demo-plant/nodes/{MM}/control") as socket:
        _enabled_on_a_panel(client, socket)
        lost = client.put(f"/api/sessions/demo-plant/simulator/nodes/{MM}/faults", json={"drop_downloads": 2})
        assert lost.status_code == 200, lost.text
    status = _until(client, MM, "switch_on_disabled", 15)
    assert status["last_trip"].startswith("Quick stop sent at "), status["last_trip"]


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
        confirm = VECTOR if step["moves"] else None
        response = confirmed(client, "POST", _url(VECTOR, f"/runs/{run['id']}/next"), json={"confirm": confirm})
        assert response.status_code == 200, response.text
        run = response.json()
        client.post(_url(VECTOR, "/keepalive"))
    assert run["failed"] is None and all(result["ok"] for result in run["results"])
    assert run["results"][1]["telegrams"][0] == {"direction": "T", "cob_id": "0x60C",
                                                 "data": "23 FE 5F 00 30 75 00 00", "t": run["results"][1][
                                                     "telegrams"][0]["t"]}
    assert client.get(_url(VECTOR, "/runs/nope")).status_code == 404


def test_each_step_shows_its_own_telegrams_while_the_control_panel_polls(client: TestClient) -> None:
    """Issue 28 item 6: with node 12's Control tab open (its status poll reads over the same SDO channel), step 2
    "C0001 := 3" shows its own download and answer, not the poll's reads of the status word and actual values."""
    with client.websocket_connect(f"/ws/sessions/demo-plant/nodes/{VECTOR}/control") as socket:
        assert socket.receive_json()["type"] == "status"  # the poll runs
        run = client.post(_url(VECTOR, "/sequences/emf-8200/runs")).json()
        while not run["finished"]:
            response = confirmed(client, "POST", _url(VECTOR, f"/runs/{run['id']}/next"), json={})
            assert response.status_code == 200, response.text
            run = response.json()
            client.post(_url(VECTOR, "/keepalive"))
            socket.send_json({"cmd": "keepalive"})
            socket.receive_json()
    assert run["failed"] is None, run["failed"]
    c0001 = run["results"][1]
    assert [(t["direction"], t["cob_id"], t["data"][:11]) for t in c0001["telegrams"]] == [
        ("T", "0x60C", "23 FE 5F 00"), ("R", "0x58C", "60 FE 5F 00"),  # the write
        ("T", "0x60C", "40 FE 5F 00"), ("R", "0x58C", "43 FE 5F 00")], c0001["telegrams"]  # its read-back
    for result in run["results"]:
        sdo = [t for t in result["telegrams"] if t["cob_id"] in ("0x60C", "0x58C")]
        assert len({t["data"][3:11] for t in sdo}) <= 1, (result["title"], sdo)  # one object per step


def test_jog_runs_only_when_enabled_and_stops_with_zero(client: TestClient) -> None:
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    refused = confirmed(client, "POST", _url(MM, "/jog"), json={"direction": 1, "confirm": MM})
    assert refused.status_code == 409 and "operation enabled" in refused.json()["detail"]
    client.post(_url(MM, "/commands/shutdown"))
    confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": MM})
    client.post(_url(MM, "/keepalive"))
    assert client.post(_url(MM, "/jog"), json={"direction": 1}).status_code == 428  # not confirmed
    assert confirmed(client, "POST", _url(MM, "/jog"), json={"direction": -1, "confirm": MM}).status_code == 200
    target = client.get(f"/api/sessions/demo-plant/nodes/{MM}/parameters/0x6042").json()
    assert target["value"] == -150  # 10 % of 0x6046.2 = 1500 rpm
    client.post(_url(MM, "/jog"), json={"direction": 0})
    assert client.get(f"/api/sessions/demo-plant/nodes/{MM}/parameters/0x6042").json()["value"] == 0
    assert client.post(_url(MM, "/jog"), json={"direction": 2}).status_code == 422


def _ws(panel: str, operator: str) -> str:
    return f"/ws/sessions/demo-plant/nodes/{MM}/control?panel={panel}&operator={operator}"


def _next_status(socket: Any) -> dict[str, Any]:
    message = socket.receive_json()
    while message["type"] != "status":
        message = socket.receive_json()
    status: dict[str, Any] = message["status"]
    return status


def test_two_panels_the_holder_moves_the_watcher_watches(client: TestClient) -> None:
    """Anna's panel enables the drive and holds it; Ben's panel sees who holds it, cannot move it, and closing it
    does not stop Anna's drive. Closing Anna's panel quick-stops."""
    _can_control(client)
    _until(client, MM, "switch_on_disabled")
    anna = {"X-Drive-Panel": "a1b2c3", "X-Drive-Operator": "Anna"}
    ben = {"X-Drive-Panel": "d4e5f6", "X-Drive-Operator": "Ben%20K."}
    client.post(_url(MM, "/commands/shutdown"), headers=anna)
    with client.websocket_connect(_ws("a1b2c3", "Anna")) as anna_socket:
        with client.websocket_connect(_ws("d4e5f6", "Ben")) as ben_socket:
            enabled = confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": MM},
                                headers=anna)
            assert enabled.json()["you_hold"]
            status = _next_status(ben_socket)
            while not status["armed"]:
                anna_socket.send_json({"cmd": "keepalive"})
                status = _next_status(ben_socket)
            assert not status["you_hold"] and status["holder"].startswith("Anna at testclient since ")
            assert status["panels"] == 2
            refused = confirmed(client, "PUT", _url(MM, "/setpoint"), json={"value": 100, "confirm": MM}, headers=ben)
            assert refused.status_code == 409 and "held by Anna at testclient" in refused.json()["detail"]
            assert client.post(_url(MM, "/keepalive"), headers=ben).json()["armed"] is False
            assert client.get(_url(MM), headers=ben).json()["holder"].startswith("Anna")
        status = _next_status(anna_socket)
        while status["panels"] != 1:  # Ben's panel closed
            anna_socket.send_json({"cmd": "keepalive"})
            status = _next_status(anna_socket)
        anna_socket.send_json({"cmd": "keepalive"})
        status = _next_status(anna_socket)
        assert status["state"] == "operation_enabled" and status["armed"] and status["you_hold"]
        assert status["last_trip"] is None
        assert client.post(_url(MM, "/keepalive"), headers=anna).json()["armed"]
    status = _until(client, MM, "switch_on_disabled")  # the holder's panel closed: quick stop
    assert "holding the drive disconnected" in status["last_trip"] and "(held by Anna" in status["last_trip"]


def test_8200_vector_jog_plan_and_device_jog(client: TestClient) -> None:
    plan = client.get(_url(VECTOR, "/jog")).json()
    assert plan["method"] == "device" and plan["value"] == 20 and plan["unit"] == "Hz"
    _plant_set(client, VECTOR, "C0001", 3)
    client.post(_url(VECTOR, "/commands/shutdown"))
    confirmed(client, "POST", _url(VECTOR, "/commands/enable_operation"), json={"confirm": VECTOR})
    jogging = confirmed(client, "POST", _url(VECTOR, "/jog"), json={"direction": -1, "confirm": VECTOR}).json()
    assert jogging["control_word"] & 0x07 == 0x05 and jogging["control_bits"][0]["set"]  # JOG1, CCW
    stopped = client.post(_url(VECTOR, "/jog"), json={"direction": 0}).json()
    assert stopped["control_word"] & 0x07 == 0
    client.post(_url(VECTOR, "/commands/disable_operation"))


def test_a_remote_diagnostics_link_cannot_drive(client: TestClient) -> None:
    """Access-control interlock: a share link holder watches the remote view only - no commands, no panel socket."""
    token = client.post("/api/share-links", json={"ttl_minutes": 5}).json()["token"]
    viewer = {"Authorization": f"Bearer {token}"}
    refused = confirmed(client, "POST", _url(MM, "/commands/enable_operation"), json={"confirm": MM}, headers=viewer)
    assert refused.status_code == 403 and refused.headers["content-type"] == "application/problem+json"
    assert confirmed(client, "POST", _url(MM, "/jog"), json={"direction": 1, "confirm": MM},
                     headers=viewer).status_code == 403
    socket_url = f"/ws/sessions/demo-plant/nodes/{MM}/control"
    with pytest.raises(WebSocketDisconnect) as closed, client.websocket_connect(socket_url, headers=viewer) as socket:
        socket.receive_json()
    assert closed.value.code == 4403


@pytest.mark.parametrize("socket", ["control", "process-data"])
def test_a_node_socket_of_an_unknown_session_or_node_closes_with_4404(client: TestClient, socket: str) -> None:
    for url, named in ((f"/ws/sessions/nope/nodes/{MM}/{socket}", "nope"),
                       (f"/ws/sessions/demo-plant/nodes/99/{socket}", "Node 99")):
        with pytest.raises(WebSocketDisconnect) as closed, client.websocket_connect(url) as opened:
            opened.receive_json()
        assert closed.value.code == 4404 and named in closed.value.reason
