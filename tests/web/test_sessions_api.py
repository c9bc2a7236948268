"""The sessions REST API and the node-state websocket, through the real app on the simulated demo plant."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import fresh_channel, wait_until

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)

DEMO = "demo-plant"
DEMO_SESSIONS = [DEMO, "ethercat-line"]  # the demo plant's CAN bus and its EtherCAT line
DEMO_DEVICES = {3: "Pump (MICROMASTER 440)", 5: "Conveyor (8400 motec)", 7: "Axis (generic CiA 402 servo)",
                12: "Fan (8200 vector + EMF2178IB)"}
PROBLEM = "application/problem+json"
# Tests marked only_reads share the module's one demo-plant app (tests/conftest.py client); the others start their own.


def node_states(client: TestClient) -> dict[int, str]:
    return {n["node_id"]: n["nmt_state"] for n in client.get(f"/api/sessions/{DEMO}/nodes").json()}


def assert_problem(response: object, status: int) -> dict[str, object]:
    assert response.status_code == status, response.text  # type: ignore[attr-defined]
    assert response.headers["content-type"].startswith(PROBLEM)  # type: ignore[attr-defined]
    body: dict[str, object] = response.json()  # type: ignore[attr-defined]
    assert body["status"] == status and body["title"] and body["detail"]
    assert "Traceback" not in response.text  # type: ignore[attr-defined]
    return body


# --- service -------------------------------------------------------------------------------------------
@pytest.mark.only_reads
def test_health(client: TestClient) -> None:
    body = client.get("/api/health").json()
    assert body["status"] == "ok" and body["sessions"] == len(DEMO_SESSIONS) and body["version"]


@pytest.mark.only_reads
def test_openapi_documents_the_sessions_api(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()
    for path in ["/api/health", "/api/interfaces", "/api/sessions", "/api/sessions/{session_id}",
                 "/api/sessions/{session_id}/nodes", "/api/sessions/{session_id}/nmt",
                 "/api/sessions/{session_id}/scan", "/api/sessions/{session_id}/nodes/{node_id}/nmt"]:
        assert path in spec["paths"], path
    assert {"SessionCreate", "SessionPublic", "NodePublic", "NmtRequest"} <= set(spec["components"]["schemas"])


@pytest.mark.only_reads
def test_interfaces_lists_python_can_interfaces(client: TestClient) -> None:
    names = client.get("/api/interfaces").json()
    assert {"socketcan", "socketcand", "pcan", "virtual", "kvaser"} <= set(names)
    assert names == sorted(names)


# --- sessions --------------------------------------------------------------------------------------------
@pytest.mark.only_reads
def test_the_demo_plant_session(client: TestClient) -> None:
    sessions = client.get("/api/sessions").json()
    assert [s["id"] for s in sessions] == DEMO_SESSIONS
    demo = client.get(f"/api/sessions/{DEMO}").json()
    assert demo["simulated"] is True and demo["bitrate"] == 500_000 and demo["interface"] == "virtual"
    assert demo["node_count"] == 4 and demo["name"] == "Demo plant" and demo["state"] == "active"


def test_open_list_and_close_a_second_session(client: TestClient) -> None:
    channel = fresh_channel()
    created = client.post("/api/sessions", json={"interface": "virtual", "channel": channel, "bitrate": 250000,
                                                 "name": "Bench 2"})
    assert created.status_code == 201, created.text
    session = created.json()
    assert session["bus"] == f"virtual:{channel}@250000" and session["simulated"] is False
    assert {s["id"] for s in client.get("/api/sessions").json()} == {*DEMO_SESSIONS, session["id"]}
    assert client.get(f"/api/sessions/{session['id']}/nodes").json() == []
    assert client.delete(f"/api/sessions/{session['id']}").status_code == 204
    assert [s["id"] for s in client.get("/api/sessions").json()] == DEMO_SESSIONS
    assert_problem(client.get(f"/api/sessions/{session['id']}"), 404)


def test_open_by_bus_text(client: TestClient) -> None:
    created = client.post("/api/sessions", json={"bus": f"virtual:{fresh_channel()}@125000"})
    assert created.status_code == 201, created.text
    assert created.json()["bitrate"] == 125000
    assert client.delete(f"/api/sessions/{created.json()['id']}").status_code == 204


@pytest.mark.only_reads
def test_opening_an_open_bus_again_is_a_conflict(client: TestClient) -> None:
    bus = client.get(f"/api/sessions/{DEMO}").json()["bus"]
    assert_problem(client.post("/api/sessions", json={"bus": bus}), 409)


@pytest.mark.only_reads
@pytest.mark.parametrize("path", [
    "/api/sessions/nope", "/api/sessions/nope/nodes", f"/api/sessions/{DEMO}/nodes/99"])
def test_unknown_session_or_node_is_404_problem(path: str, client: TestClient) -> None:
    body = assert_problem(client.get(path), 404)
    assert "nope" in str(body["detail"]) or "99" in str(body["detail"])


@pytest.mark.only_reads
def test_closing_an_unknown_session_is_404(client: TestClient) -> None:
    assert_problem(client.delete("/api/sessions/nope"), 404)


# --- bad input ---------------------------------------------------------------------------------------------
@pytest.mark.only_reads
def test_wrong_interface_name_says_which_and_what_to_check(client: TestClient) -> None:
    body = assert_problem(client.post("/api/sessions", json={"interface": "socketcann", "channel": "can0"}), 503)
    assert "socketcann" in str(body["detail"])
    assert "socketcan" in str(body["hint"]) and "virtual" in str(body["hint"])


@pytest.mark.only_reads
def test_missing_adapter_names_the_interface_and_a_fix(client: TestClient) -> None:
    body = assert_problem(client.post("/api/sessions", json={"bus": "pcan:PCAN_USBBUS1@250000"}), 503)
    assert "pcan:PCAN_USBBUS1@250000" in str(body["detail"])
    assert "PEAK" in str(body["hint"])


@pytest.mark.only_reads
def test_unreachable_gateway_names_host_and_port(client: TestClient) -> None:
    body = assert_problem(client.post("/api/sessions", json={"bus": "socketcand:127.0.0.1:9/can0"}), 503)
    assert "127.0.0.1:9" in str(body["detail"]) and "socketcand" in str(body["hint"])


@pytest.mark.only_reads
def test_malformed_bus_text_is_422(client: TestClient) -> None:
    body = assert_problem(client.post("/api/sessions", json={"bus": "can0"}), 422)
    assert "INTERFACE:CHANNEL@BITRATE" in str(body["detail"])


@pytest.mark.only_reads
@pytest.mark.parametrize("payload", [
    {"interface": "virtual", "channel": "x", "bitrate": 2_000_000},
    {"interface": "virtual", "channel": "x", "bitrate": 0},
    {"bus": "virtual:x@5000000"},
    {"channel": "can0"},
    {"interface": "virtual", "channel": "x", "bitrate": "fast"},
])
def test_invalid_session_requests_are_422(payload: dict[str, object], client: TestClient) -> None:
    assert_problem(client.post("/api/sessions", json=payload), 422)
    assert [s["id"] for s in client.get("/api/sessions").json()] == DEMO_SESSIONS


@pytest.mark.only_reads
@pytest.mark.parametrize(("path", "payload"), [
    (f"/api/sessions/{DEMO}/nmt", {"command": "jump"}),
    (f"/api/sessions/{DEMO}/nmt", {"command": "start", "node_id": 128}),
    (f"/api/sessions/{DEMO}/nodes/5/nmt", {"command": "reboot"}),
    (f"/api/sessions/{DEMO}/scan", {"timeout_s": 60}),
])
def test_invalid_nmt_and_scan_requests_are_422(path: str, payload: dict[str, object], client: TestClient) -> None:
    assert_problem(client.post(path, json=payload), 422)


# --- nodes, NMT, scan ---------------------------------------------------------------------------------------
@pytest.mark.only_reads
def test_nodes_list_device_names_and_heartbeat_states(client: TestClient) -> None:
    assert wait_until(lambda: set(node_states(client).values()) == {"Pre-operational"})
    nodes = client.get(f"/api/sessions/{DEMO}/nodes").json()
    assert {n["node_id"]: n["device"] for n in nodes} == DEMO_DEVICES
    for node in nodes:
        assert node["state_from_heartbeat"] is True and node["heartbeat_lost"] is False
        assert node["heartbeat_age_s"] is not None and node["heartbeat_age_s"] < 5
        assert node["profile_id"]


def test_nmt_broadcast_and_per_node(client: TestClient) -> None:
    assert wait_until(lambda: set(node_states(client).values()) == {"Pre-operational"})
    assert client.post(f"/api/sessions/{DEMO}/nmt", json={"command": "start"}).status_code == 428
    answer = confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt",
                       json={"command": "start", "confirm": "all", **NO_BROWSER})
    assert answer.status_code == 200 and len(answer.json()) == 4
    assert wait_until(lambda: set(node_states(client).values()) == {"Operational"})
    single = client.post(f"/api/sessions/{DEMO}/nodes/12/nmt", json={"command": "stop"})
    assert single.status_code == 200 and single.json()["node_id"] == 12
    assert wait_until(lambda: node_states(client) == {3: "Operational", 5: "Operational", 7: "Operational",
                                                      12: "Stopped"})
    client.post(f"/api/sessions/{DEMO}/nmt", json={"command": "pre-operational", "node_id": 5})
    assert wait_until(lambda: node_states(client) == {3: "Operational", 5: "Pre-operational", 7: "Operational",
                                                      12: "Stopped"})
    bootups = client.get(f"/api/sessions/{DEMO}/nodes/3").json()["bootups"]
    reset = confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt", json={"command": "reset-node"})
    assert reset.status_code == 200, reset.text
    assert wait_until(lambda: client.get(f"/api/sessions/{DEMO}/nodes/3").json()["bootups"] > bootups)
    assert wait_until(lambda: set(node_states(client).values()) == {"Pre-operational"})


def test_scan_finds_the_four_demo_nodes(client: TestClient) -> None:
    found = client.post(f"/api/sessions/{DEMO}/scan", json={"timeout_s": 0.3})
    assert found.status_code == 200, found.text
    assert {n["node_id"]: n["device"] for n in found.json()} == DEMO_DEVICES
    assert client.post(f"/api/sessions/{DEMO}/scan").status_code == 200  # the body is optional


def test_add_and_remove_a_node(client: TestClient) -> None:
    added = client.post(f"/api/sessions/{DEMO}/nodes", json={"node_id": 40, "profile_id": "lenze-8400-motec-canopen"})
    assert added.status_code == 201, added.text
    assert added.json()["nmt_state"] == "Unknown" and added.json()["heartbeat_age_s"] is None
    assert client.delete(f"/api/sessions/{DEMO}/nodes/40").status_code == 204
    assert 40 not in node_states(client)
    assert_problem(client.post(f"/api/sessions/{DEMO}/nodes", json={"node_id": 41, "profile_id": "no-such"}), 404)


# --- websocket -----------------------------------------------------------------------------------------------
def test_node_websocket_pushes_the_nodes_table_as_it_changes(client: TestClient) -> None:
    assert wait_until(lambda: set(node_states(client).values()) == {"Pre-operational"})
    with client.websocket_connect(f"/ws/sessions/{DEMO}/nodes") as socket:
        first = socket.receive_text()
        assert f'id="nodes-{DEMO}" hx-swap-oob="true"' in first
        for device in ("Pump (MICROMASTER 440)", "Conveyor (8400 motec)", "Fan (8200 vector + EMF2178IB)"):
            assert device in first
        assert first.count("Pre-operational") >= 3
        confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt",
                  json={"command": "start", "confirm": "all", **NO_BROWSER})
        for _ in range(20):
            update = socket.receive_text()
            if update.count(">Operational<") == 4:
                break
        else:
            raise AssertionError("the websocket never showed four Operational nodes")


@pytest.mark.only_reads
def test_node_websocket_of_an_unknown_session_closes(client: TestClient) -> None:
    from starlette.websockets import WebSocketDisconnect

    with client.websocket_connect("/ws/sessions/nope/nodes") as socket, pytest.raises(WebSocketDisconnect) as closed:
        socket.receive_text()
    assert closed.value.code == 4404


def test_a_broadcast_reset_asks_for_all_nodes_and_waits_for_the_drives_to_stop(client: TestClient) -> None:
    """NMT reset communication / reset node of all nodes reaches every device on the bus (issue 32): the 428 names
    all nodes and the command, nothing is sent before the confirmation, and while a node is armed it is refused in
    words; one node's reset stays open to anyone, as stopping is."""
    bootups = client.get(f"/api/sessions/{DEMO}/nodes/3").json()["bootups"]
    asked = client.post(f"/api/sessions/{DEMO}/nmt", json={"command": "reset-communication"})
    problem = assert_problem(asked, 428)
    assert problem["confirm_node"] == "all"
    assert problem["confirm_values"] == {"reaches": "all nodes on this bus", "NMT": "reset-communication"}
    started = confirmed(client, "POST", f"/api/sessions/{DEMO}/nodes/7/nmt", json={"command": "start"})
    assert started.status_code == 200, started.text  # armed: the keep-alive guard holds node 7
    refused = confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt", json={"command": "reset-communication"})
    detail = assert_problem(refused, 409)["detail"]
    assert detail == ("NMT reset communication of all nodes reaches every device on the bus: refused while node 7 is "
                      "enabled or armed. Disable or stop it first (Control tab, or NMT pre-operational).")
    assert client.get(f"/api/sessions/{DEMO}/nodes/3").json()["bootups"] == bootups  # nothing was sent
    single = client.post(f"/api/sessions/{DEMO}/nodes/3/nmt", json={"command": "reset-communication"})
    assert single.status_code == 200, single.text
    assert wait_until(lambda: client.get(f"/api/sessions/{DEMO}/nodes/3").json()["bootups"] > bootups)
    client.post(f"/api/sessions/{DEMO}/nodes/7/nmt", json={"command": "pre-operational"})
    reset = confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt", json={"command": "reset-communication"})
    assert reset.status_code == 200, reset.text
