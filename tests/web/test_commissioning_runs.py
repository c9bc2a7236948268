"""A guided commissioning run over the real HTTP API on the simulated demo plant belongs to the node and the writer
that started it (issue 27 item 5), and each of its SDO steps is the one checked write (issue 30 item 2): range
check with the range in the refusal, an audit row with the origin "commissioning", the node's write lease held by
the run's writer, the moving-write confirmation. The wire is watched for what reaches a node."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.services.control import commissioning
from drivebench.services.control.commissioning import Run
from drivebench.simulator.node import SimulatedNode
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT

DEMO = "demo-plant"
MOTEC, VECTOR = 5, 12
ANNA = {"X-DriveBench-User": "anna", "X-DriveBench-Client": "tab-anna"}
BEN = {"X-DriveBench-User": "ben", "X-DriveBench-Client": "tab-ben"}
C0135, C0001 = 0x5F78, 0x5FFE  # Lenze code -> index: 0x5FFF - code


@pytest.fixture
def api(channel: str, app_db_url: str) -> Iterator[TestClient]:
    """The real app with the demo plant on the test's channel (``wire`` records it) and a database of its own."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def _url(node: int, tail: str) -> str:
    return f"/api/sessions/{DEMO}/nodes/{node}/control{tail}"


def _sim(client: TestClient, node: int) -> SimulatedNode:
    sim: SimulatedNode = client.app.state.drivebench.plants[DEMO].nodes[node]  # type: ignore[attr-defined]
    return sim


def _server_run(client: TestClient, run_id: str) -> Run:
    session = client.app.state.drivebench.manager.get(DEMO)  # type: ignore[attr-defined]
    return commissioning.wizard(session).runs[run_id]


def _start(client: TestClient, headers: dict[str, str], node: int = VECTOR) -> dict[str, Any]:
    answer = client.post(_url(node, "/sequences/emf-8200/runs"), headers=headers)
    assert answer.status_code == 201, answer.text
    run: dict[str, Any] = answer.json()
    return run


def _downloads(wire: can.BusABC, node: int, index: int | None = None) -> list[can.Message]:
    """SDO download requests to ``node`` (to ``index``) the wire carried since the last call (a virtual bus queues a
    frame when it is sent: what the requests so far sent is there)."""
    seen = []
    while (msg := wire.recv(timeout=0)) is not None:
        if (msg.arbitration_id == 0x600 + node and msg.data[0] & 0xE0 == 0x20
                and (index is None or int.from_bytes(msg.data[1:3], "little") == index)):
            seen.append(msg)
    return seen


def _audit(client: TestClient, node: int) -> list[dict[str, Any]]:
    answer = client.get("/api/audit", params={"node_id": node}, headers=ANNA)
    assert answer.status_code == 200, answer.text
    rows: list[dict[str, Any]] = answer.json()
    return rows


def test_a_run_of_node_12_is_not_driven_through_node_5(api: TestClient, wire: can.BusABC) -> None:
    """The reported case: a run started for node 12, its next step asked through node 5's URL (and confirmed with
    node 5): refused in words, and not a frame reaches node 5."""
    run = _start(api, ANNA)
    _downloads(wire, MOTEC)
    for body in ({}, {"confirm": MOTEC}):
        refused = api.post(_url(MOTEC, f"/runs/{run['id']}/next"), json=body, headers=ANNA)
        assert refused.status_code == 404, refused.text
        assert refused.headers["content-type"] == "application/problem+json"
        assert "belongs to node 12" in refused.json()["detail"] and "node 5" in refused.json()["detail"]
    assert api.get(_url(MOTEC, f"/runs/{run['id']}"), headers=ANNA).status_code == 404
    assert _downloads(wire, MOTEC) == [], "nothing was sent to node 5"
    assert _audit(api, MOTEC) == []

    step = api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=ANNA)  # its own node runs it
    assert step.status_code == 200 and step.json()["position"] == 1, step.text
    assert [bytes(m.data[:4]) for m in _downloads(wire, VECTOR, C0135)] == [bytes.fromhex("2b 78 5f 00")]


def test_a_step_is_a_write_in_the_audit_log(api: TestClient) -> None:
    run = _start(api, ANNA)
    step = api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=ANNA)
    assert step.status_code == 200 and step.json()["results"][0]["ok"], step.text
    rows = _audit(api, VECTOR)
    assert [(row["ref"], row["new_value"], row["origin"], row["result"]) for row in rows] == [
        ("C0135", "0x0200", "commissioning", "written")], rows  # a parameter step reads back (issue 30 item 3)
    assert _sim(api, VECTOR).store.get(C0135, 0) == 0x0200


def test_a_step_value_outside_the_profile_range_is_refused_with_the_range(api: TestClient,
                                                                          wire: can.BusABC) -> None:
    """The profile's C0001 (operating mode) takes 0 ... 3; a step value of 4 is refused before anything is
    sent, with the range in the words, and the run stays at that step."""
    run = _start(api, ANNA)
    second = _server_run(api, run["id"]).sequence.steps[1]
    assert (second.kind, second.ref) == ("parameter", "C0001")
    assert api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=ANNA).status_code == 200
    before = _sim(api, VECTOR).store.get(C0001, 0)
    _downloads(wire, VECTOR)
    refused = confirmed(api, "POST", _url(VECTOR, f"/runs/{run['id']}/next"), json={"value": 4}, headers=ANNA)
    assert refused.status_code == 422, refused.text
    assert refused.headers["content-type"] == "application/problem+json"
    detail = refused.json()["detail"]
    assert "C0001" in detail and "outside the allowed range 0.0000 ... 3.0000" in detail, detail
    assert _downloads(wire, VECTOR, C0001) == [] and _sim(api, VECTOR).store.get(C0001, 0) == before
    current = api.get(_url(VECTOR, f"/runs/{run['id']}"), headers=ANNA).json()
    assert current["position"] == 1 and current["failed"] is None
    assert [row["ref"] for row in _audit(api, VECTOR)] == ["C0135"]


def test_a_second_engineer_cannot_run_steps_while_the_run_holds_the_lease(api: TestClient,
                                                                           wire: can.BusABC) -> None:
    run = _start(api, ANNA)
    _downloads(wire, VECTOR)
    taken = api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=BEN)
    assert taken.status_code == 409, taken.text
    assert "started by anna" in taken.json()["detail"], taken.json()
    own = api.post(_url(VECTOR, "/sequences/emf-8200/runs"), headers=BEN)
    assert own.status_code == 409 and "being written by anna" in own.json()["detail"], own.text
    write = api.put(f"/api/sessions/{DEMO}/nodes/{VECTOR}/parameters/C0012", json={"value": 5}, headers=BEN)
    assert write.status_code == 409 and "being written by anna" in write.json()["detail"], write.text
    assert _downloads(wire, VECTOR) == [], "nothing of ben's reached node 12"
    assert api.get(_url(VECTOR, f"/runs/{run['id']}"), headers=BEN).json()["position"] == 0  # he may watch it
    mine = api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=ANNA)
    assert mine.status_code == 200 and mine.json()["position"] == 1, mine.text


def test_a_moving_step_needs_the_confirmation_of_its_node(api: TestClient, wire: can.BusABC) -> None:
    """C0001 := 3 hands the drive to the fieldbus (a command source): 428 naming node 12, nothing sent; confirmed,
    it is written, logged and arms the keep-alive guard for the run's panel."""
    run = _start(api, ANNA)
    assert run["steps"][1]["moves"] and not run["steps"][0]["moves"]
    assert api.post(_url(VECTOR, f"/runs/{run['id']}/next"), json={}, headers=ANNA).status_code == 200
    _downloads(wire, VECTOR)
    url = _url(VECTOR, f"/runs/{run['id']}/next")
    asked = api.post(url, json={}, headers=ANNA)
    assert asked.status_code == 428 and asked.json()["confirm_node"] == VECTOR, asked.text
    assert "Step 2" in asked.json()["detail"]
    assert api.post(url, json={"confirm": MOTEC}, headers=ANNA).status_code == 428, "node 5 confirms nothing here"
    assert _downloads(wire, VECTOR, C0001) == [] and _sim(api, VECTOR).store.get(C0001, 0) != 30000
    done = confirmed(api, "POST", url, json={}, headers=ANNA)
    assert done.status_code == 200 and done.json()["position"] == 2, done.text
    assert _sim(api, VECTOR).store.get(C0001, 0) == 30000
    assert [(row["ref"], row["origin"]) for row in _audit(api, VECTOR)] == [
        ("C0001", "commissioning"), ("C0135", "commissioning")]
    assert api.post(_url(VECTOR, "/keepalive"), headers=ANNA).json()["armed"]
