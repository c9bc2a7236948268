"""Safety interlocks over the real HTTP and websocket path on the simulated demo plant: confirmation of NMT start
(428 without it), the keep-alive of what a client started (lost keep-alive, closed page socket -> quick stop and NMT
pre-operational on the wire), and the per-node write lease between two engineers (409 with the holder's name, never
interleaved on the wire, release, expiry, admin break)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient
from starlette.types import ASGIApp, Receive, Scope, Send

from drivebench.services.params import node_lease
from drivebench.services.users.principals import Principal, Role
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, wait_until

DEMO = "demo-plant"
MM, MOTEC = 3, 5
ANNA = {"X-DriveBench-User": "anna", "X-DriveBench-Client": "tab-anna"}
BEN = {"X-DriveBench-User": "ben", "X-DriveBench-Client": "tab-ben"}
REF, INDEX = "C00039/1", 0x5FFF - 39  # 8400 motec Fixed setpoint-JOG1, INTEGER16 % x 100


def _node(path: str = "", node: int = MOTEC) -> str:
    return f"/api/sessions/{DEMO}/nodes/{node}{path}"


def _plant(client: TestClient) -> Plant:
    plant: Plant = client.app.state.drivebench.plants[DEMO]  # type: ignore[attr-defined]
    return plant


class Frames:
    """What the wire carried so far (read on demand)."""

    def __init__(self, wire: can.BusABC) -> None:
        self.wire, self.seen = wire, []  # type: ignore[var-annotated]

    def drain(self) -> list[can.Message]:
        while (msg := self.wire.recv(timeout=0.01)) is not None:
            self.seen.append(msg)
        return self.seen

    def nmt(self, command: int, node: int) -> bool:
        return any(m.arbitration_id == 0 and bytes(m.data[:2]) == bytes([command, node]) for m in self.drain())

    def sdo_download(self, node: int, index: int) -> list[can.Message]:
        return [m for m in self.drain() if m.arbitration_id == 0x600 + node and m.data[0] & 0xE0 == 0x20
                and int.from_bytes(m.data[1:3], "little") == index]


# --- confirmation ----------------------------------------------------------------------------------------------
def test_nmt_start_needs_the_confirmation_naming_the_node(client: TestClient, wire: can.BusABC) -> None:
    frames = Frames(wire)
    refused = client.post(_node("/nmt"), json={"command": "start"})
    assert refused.status_code == 428 and refused.headers["content-type"] == "application/problem+json"
    assert "NMT start lets node 5 move a drive: confirm it" in refused.json()["detail"]
    assert confirmed(client, "POST", _node("/nmt"),
                     json={"command": "start", "confirm": 3}).status_code == 428  # wrong node
    assert confirmed(client, "POST", f"/api/sessions/{DEMO}/nmt",
                     json={"command": "start", "confirm": 5}).status_code == 428
    page = client.post(f"/ui/sessions/{DEMO}/nmt", data={"command": "start", "node_id": "5"})
    assert page.status_code == 428 and "confirm" in page.text
    assert not frames.nmt(0x01, MOTEC) and not frames.nmt(0x01, 0), "nothing started without the confirmation"
    assert client.post(_node("/nmt"), json={"command": "start"},
                       headers={"X-DriveBench-Confirm": "5"}).status_code == 428  # the node without the values
    by_header = client.post(_node("/nmt"), json={"command": "start"},
                            headers={"X-DriveBench-Confirm": "5", "X-DriveBench-Confirm-Values": '{"NMT": "start"}'})
    assert by_header.status_code == 200 and frames.nmt(0x01, MOTEC)
    stopping = client.post(_node("/nmt"), json={"command": "pre-operational"})  # leaving Operational: no question
    assert stopping.status_code == 200 and frames.nmt(0x80, MOTEC)


def test_keepalive_false_needs_a_reason(client: TestClient) -> None:
    no_reason = confirmed(client, "POST", _node("/nmt"), json={"command": "start", "confirm": 5, "keepalive": False})
    assert no_reason.status_code == 422 and "reason" in no_reason.json()["detail"]


# --- keep-alive ------------------------------------------------------------------------------------------------
def test_api_client_that_stops_its_keepalive_gets_its_node_stopped(client: TestClient, wire: can.BusABC) -> None:
    """NMT start of the MICROMASTER with a 1 s keep-alive; the script keeps it alive a while, then goes silent: the
    server writes quick stop to 0x6040 and sends NMT pre-operational, both on the wire."""
    frames = Frames(wire)
    sim = _plant(client).nodes[MM]
    started = confirmed(client, "POST", _node("/nmt", MM), json={"command": "start", "confirm": 3, "keepalive_s": 1})
    assert started.status_code == 200
    assert wait_until(lambda: sim.state.name == "OPERATIONAL")
    until = time.monotonic() + 2.5
    while time.monotonic() < until:  # kept alive for longer than the timeout: nothing stops
        kept = client.post(f"/api/sessions/{DEMO}/keepalive").json()
        assert kept["nodes"] == [MM] and kept["timeout_s"] == 1
        time.sleep(0.3)
    assert not frames.nmt(0x80, MM) and sim.state.name == "OPERATIONAL"
    assert wait_until(lambda: frames.nmt(0x80, MM)), "no NMT pre-operational after the keep-alive stopped"
    assert frames.sdo_download(MM, 0x6040), "no quick stop written to the control word"
    assert wait_until(lambda: sim.state.name == "PRE_OPERATIONAL")
    word = next(m for m in frames.sdo_download(MM, 0x6040))
    assert word.data[4] & 0x06 == 0x02, "CiA 402 quick stop: bit 1 set, bit 2 cleared"
    assert client.post(f"/api/sessions/{DEMO}/keepalive").json()["nodes"] == []


def test_closing_the_page_socket_stops_what_it_started(client: TestClient, wire: can.BusABC) -> None:
    """The Plant page's keep-alive socket holds the 8400 motec it started; the page closes -> NMT pre-operational
    and quick stop (C00866/1, the CAN1_IN control word) within the keep-alive timeout."""
    frames = Frames(wire)
    sim = _plant(client).nodes[MOTEC]
    with client.websocket_connect(f"/ws/sessions/{DEMO}/keepalive?client=tab-anna") as socket:
        started = confirmed(client, "POST", f"/ui/sessions/{DEMO}/nmt",
                            data={"command": "start", "node_id": "5", "confirm": "5"},
                            headers=ANNA)
        assert started.status_code == 200
        assert wait_until(lambda: sim.state.name == "OPERATIONAL")
        for _ in range(8):  # the page's keep-alive, 4 s in all: longer than the 2 s timeout
            socket.send_text('{"cmd": "keepalive"}')
            assert socket.receive_json() == {"type": "held", "nodes": [MOTEC], "not_held": []}
            time.sleep(0.5)
        assert not frames.nmt(0x80, MOTEC) and sim.state.name == "OPERATIONAL"
        ben = confirmed(client, "POST", _node("/nmt"), json={"command": "start", "confirm": 5}, headers=BEN)
        assert ben.status_code == 409 and "anna" in ben.json()["detail"], "another client cannot take the node"
    assert wait_until(lambda: frames.nmt(0x80, MOTEC)), "the closed page's node was not stopped"
    assert frames.sdo_download(MOTEC, 0x5FFF - 866), "no quick stop written to C00866/1"
    assert wait_until(lambda: sim.state.name == "PRE_OPERATIONAL")
    trip = client.get(_node("/control")).json()["last_trip"]
    assert "the page that started it disconnected" in trip and "NMT pre-operational sent" in trip, trip
    assert client.get(_node("/control", MM)).json()["last_trip"] is None  # the other nodes are untouched


def test_the_same_tab_reconnecting_keeps_its_node_running(client: TestClient, wire: can.BusABC) -> None:
    """An in-app navigation closes the page's socket and the next page opens one for the same tab: no stop."""
    frames = Frames(wire)
    url = f"/ws/sessions/{DEMO}/keepalive?client=tab-anna"
    with client.websocket_connect(url) as socket:
        assert confirmed(client, "POST", _node("/nmt"), json={"command": "start", "confirm": 5},
                         headers=ANNA).status_code == 200
        socket.send_text("{}")
        assert socket.receive_json()["nodes"] == [MOTEC]
    with client.websocket_connect(url) as socket:  # the next page of the same tab
        for _ in range(8):
            socket.send_text("{}")
            assert socket.receive_json()["nodes"] == [MOTEC]
            time.sleep(0.5)
        assert not frames.nmt(0x80, MOTEC), "stopped although the tab came back"
    assert wait_until(lambda: frames.nmt(0x80, MOTEC)), "not stopped after the tab left for good"


def test_cyclic_rpdo_page_closed_stops_the_frames_and_the_drive(client: TestClient, wire: can.BusABC) -> None:
    frames = Frames(wire)
    mapped = client.put(_node("/pdos/rpdo/5", MM), json={"entries": [[0x6040, 0], [0x6042, 0]]}, headers=ANNA)
    assert mapped.status_code == 200
    confirmed(client, "POST", _node("/nmt", MM),
              json={"command": "start", "confirm": 3, "keepalive": False, "reason": "test"},
              headers=ANNA)
    with client.websocket_connect(f"/ws/sessions/{DEMO}/keepalive?client=tab-anna") as keepalive, \
            client.websocket_connect(f"/ws/sessions/{DEMO}/nodes/{MM}/process-data") as live:
        owner = live.receive_json()["client_id"]
        sent = confirmed(client, "POST", f"/ui/sessions/{DEMO}/nodes/{MM}/pdo/rpdo/5/send", headers=ANNA, data={
                          "mode": "cyclic", "client_id": owner, "period_ms": "50", "v:0x6040": "15", "v:0x6042": "100",
                          "confirm": "3"})
        assert sent.status_code == 200, sent.text
        keepalive.send_text("{}")
        assert keepalive.receive_json()["nodes"] == [MM]
        assert wait_until(lambda: sum(m.arbitration_id == 0x303 for m in frames.drain()) >= 3)
    assert wait_until(lambda: len(frames.sdo_download(MM, 0x6040)) >= 1), "no quick stop after the page closed"
    quiet_from = len(frames.drain())
    time.sleep(0.5)
    assert not [m for m in frames.drain()[quiet_from:] if m.arbitration_id == 0x303], "RPDO5 still sent"


# --- write lease -----------------------------------------------------------------------------------------------
def _write(client: TestClient, headers: dict[str, str], value: float) -> Any:
    return client.put(_node(f"/parameters/{REF}"), json={"value": value, "verify": False}, headers=headers)


def test_second_engineer_sees_who_holds_the_node(client: TestClient) -> None:
    assert _write(client, ANNA, 12).status_code == 200
    assert _write(client, ANNA, 13).status_code == 200  # the holder writes freely
    refused = _write(client, BEN, 20)
    assert refused.status_code == 409 and refused.headers["content-type"] == "application/problem+json"
    body = refused.json()
    assert body["detail"].startswith("Node 5 is being written by anna (since ")
    assert "Parameters API" in body["detail"] and "the lease expires in" in body["detail"]
    assert body["holder"] == "anna" and 0 < body["expires_in_s"] <= node_lease.LEASE_TTL_S
    lease = client.get(_node("/lease"), headers=BEN).json()
    assert lease["holder"] == "anna" and not lease["yours"]
    assert client.get(_node("/lease"), headers=ANNA).json()["yours"]
    # the node page shows the banner with the same words
    banner = client.get(f"/ui/sessions/{DEMO}/nodes/{MOTEC}/lease", headers=BEN).text
    assert "held-by-other" in banner and "Node 5 is being written by anna" in banner and "Break lease" in banner
    # ben's PDO apply and drive control are refused too; stopping is not
    assert client.put(_node("/pdos/rpdo/1"), json={"entries": []}, headers=BEN).status_code == 409
    # ... and so is the heartbeat set-up on the Diagnostics tab (API and page)
    heartbeat = client.put(_node("/heartbeat/producer"), json={"time_ms": 300}, headers=BEN)
    assert heartbeat.status_code == 409 and "anna" in heartbeat.json()["detail"]
    page = client.post(f"/ui/sessions/{DEMO}/nodes/{MOTEC}/diagnostics/producer", data={"time_ms": "300"},
                       headers=BEN)
    assert "Node 5 is being written by anna" in page.text
    stop = client.post(_node("/control/commands/quick_stop"), headers=BEN)
    assert stop.status_code == 200, "any station may stop the drive"
    assert client.delete(_node("/lease"), headers=ANNA).json()["holder"] is None  # released
    assert _write(client, BEN, 20).status_code == 200


def test_concurrent_writes_of_two_engineers_never_interleave(client: TestClient, wire: can.BusABC) -> None:
    frames = Frames(wire)
    values = {"anna": 11.11, "ben": 22.22}

    def write(who: dict[str, str]) -> int:
        return int(_write(client, who, values[who["X-DriveBench-User"]]).status_code)

    with ThreadPoolExecutor(max_workers=4) as pool:
        codes = list(pool.map(write, [ANNA, BEN] * 6))
    assert sorted(set(codes)) == [200, 409], codes
    winner = "anna" if codes[0] == 200 else "ben"
    on_wire = [int.from_bytes(m.data[4:6], "little") for m in frames.sdo_download(MOTEC, INDEX)]
    assert on_wire and set(on_wire) == {round(values[winner] * 100)}, on_wire
    assert len(on_wire) == codes.count(200)


def test_lease_expires_after_silence(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    assert _write(client, ANNA, 12).status_code == 200
    assert _write(client, BEN, 20).status_code == 409
    monkeypatch.setattr(node_lease, "LEASE_TTL_S", 0.0)
    assert client.get(_node("/lease"), headers=BEN).json()["holder"] is None
    assert _write(client, BEN, 20).status_code == 200


class _As:
    """Puts a principal into the scope, as the access-control middleware will."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            headers = dict(scope.get("headers") or [])
            role = headers.get(b"x-test-role")
            if role:
                name = headers.get(b"x-drivebench-user", b"someone").decode()
                scope.setdefault("state", {})["principal"] = Principal(name, Role.parse(role.decode()), via="login")
        await self.app(scope, receive, send)


@pytest.fixture
def roles_client(channel: str) -> Iterator[TestClient]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    app.add_middleware(_As)
    with TestClient(app) as test_client:
        yield test_client


def test_admin_breaks_a_lease_an_engineer_cannot(roles_client: TestClient) -> None:
    anna = {**ANNA, "X-Test-Role": "engineer"}
    ben = {**BEN, "X-Test-Role": "engineer"}
    admin = {"X-DriveBench-User": "root", "X-DriveBench-Client": "tab-root", "X-Test-Role": "admin"}
    assert _write(roles_client, anna, 12).status_code == 200
    refused = roles_client.delete(_node("/lease"), params={"force": "true"}, headers=ben)
    assert refused.status_code == 403
    page_break = roles_client.post(f"/ui/sessions/{DEMO}/nodes/{MOTEC}/lease/break", headers=ben)
    assert page_break.status_code == 403
    broken = roles_client.delete(_node("/lease"), params={"force": "true"}, headers=admin)
    assert broken.status_code == 200 and broken.json()["holder"] is None
    assert _write(roles_client, ben, 20).status_code == 200
    no_guard = confirmed(roles_client, "POST", _node("/nmt"),
                         json={"command": "start", "confirm": 5, "keepalive": False, "reason": "PLC supervises"},
                         headers=ben)
    assert no_guard.status_code == 403, "only admins start without the keep-alive guard"


def test_a_closed_tab_ends_its_leases_and_the_same_engineer_takes_over_a_script(client: TestClient) -> None:
    anna_tab2 = {"X-DriveBench-User": "anna", "X-DriveBench-Client": "tab-anna-2"}
    with client.websocket_connect(f"/ws/sessions/{DEMO}/keepalive?client=tab-anna"):
        assert _write(client, ANNA, 12).status_code == 200
        refused = _write(client, anna_tab2, 13)  # her other tab, while the first one is open: refused too
        assert refused.status_code == 409 and "anna" in refused.json()["detail"]
    assert wait_until(lambda: client.get(_node("/lease")).json()["holder"] is None), "the closed tab kept its lease"
    script = {"X-DriveBench-User": "anna"}  # anna's script: no page open
    assert _write(client, script, 14).status_code == 200
    assert _write(client, BEN, 20).status_code == 409, "another engineer still waits"
    assert _write(client, anna_tab2, 15).status_code == 200, "the same engineer's tab takes over from her script"
    assert client.get(_node("/lease"), headers=anna_tab2).json()["yours"]
