"""Batch writes (``POST …/parameters:write``) through the real HTTP API against the simulated demo plant: all items
validated first (one invalid refuses the batch, each item's problem in words, nothing sent), a moving write in the
batch needs the confirmation naming the node (428 and nothing written without it; with it the guard is armed), then
written in order through the single write's path (one audit row each) until the first device error, the node's
lease honoured, a viewer refused."""

from __future__ import annotations

import json
from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.web.test_access import app_client, own_db, users  # noqa: F401  (fixtures)
from tests.web.test_moving_writes import DEMO, MM, _bearer, _keepalive, _sim

BATCH = f"/api/sessions/{DEMO}/nodes/{MM}/parameters:write"


def _audit(client: TestClient, headers: dict[str, str]) -> list[dict[str, Any]]:
    answer = client.get("/api/audit", params={"node_id": MM}, headers=headers)
    assert answer.status_code == 200, answer.text
    rows: list[dict[str, Any]] = answer.json()
    return rows


def test_an_invalid_item_refuses_the_whole_batch_with_each_items_problem(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    eve = _bearer(users["eve"])
    sim = _sim(app_client, MM)
    before = sim.store.get_ref("P1120")
    answer = app_client.post(BATCH, headers=eve, json={"items": [
        {"ref": "P1120", "value": 4.5}, {"ref": "P1121", "value": "fast"}, {"ref": "C99999", "value": 1},
        {"ref": "0x1000.0", "raw": 5}]})
    assert answer.status_code == 422, answer.text
    assert answer.headers["content-type"] == "application/problem+json"
    problem = answer.json()
    assert "3 of the 4 values of the batch are not valid, so none was written" in problem["detail"]
    items = problem["items"]
    assert [(item["ref"], item["ok"]) for item in items] == [
        ("P1120", True), ("P1121", False), ("C99999", False), ("0x1000.0", False)]
    assert "fast" in items[1]["error"]["detail"]
    assert "C99999" in items[2]["error"]["detail"] and items[2]["error"]["status"] == 404
    assert "read-only" in items[3]["error"]["detail"] and items[3]["error"]["status"] == 422, items[3]
    assert sim.store.get_ref("P1120") == before, "the valid item was not written either"
    assert _audit(app_client, eve) == []


def test_a_moving_write_in_a_batch_needs_the_confirmation_naming_the_node(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    eve = _bearer(users["eve"])
    sim = _sim(app_client, MM)
    items = [{"ref": "P1120", "value": 4.5}, {"ref": "P0700", "value": 6}]
    refused = app_client.post(BATCH, headers=eve, json={"items": items})
    assert refused.status_code == 428, refused.text
    assert f"lets node {MM} move a drive: confirm it with confirm = '{MM}'" in refused.json()["detail"]
    assert "P0700" in refused.json()["detail"]
    wrong = confirmed(app_client, "POST", BATCH, headers=eve, json={"items": items, "confirm": "true"})
    assert wrong.status_code == 428, "a bare true does not name the node"
    assert sim.store.get_ref("P1120") != 4.5 and sim.store.get_ref("P0700") != 6, "nothing was written"
    assert _audit(app_client, eve) == []
    assert _keepalive(app_client, eve)["nodes"] == [], "nothing armed"

    done = confirmed(app_client, "POST", BATCH, headers=eve, json={"items": items, "confirm": MM})
    assert done.status_code == 200, done.text
    answer = done.json()
    assert answer["complete"] and answer["written"] == 2
    assert [(item["ref"], item["state"]) for item in answer["items"]] == [("P1120", "written"), ("P0700", "written")]
    assert answer["items"][1]["result"]["verified"] is True
    assert sim.store.get_ref("P1120") == 4.5 and sim.store.get_ref("P0700") == 6
    assert _keepalive(app_client, eve)["nodes"] == [MM], "the confirmed moving write armed the guard for eve"
    rows = _audit(app_client, eve)
    assert sorted((row["ref"], row["result"], row["user"]) for row in rows) == [
        ("P0700", "written", "eve"), ("P1120", "written", "eve")], "one audit row per write"


def test_the_header_confirms_a_batch_too_and_a_stopping_control_word_needs_none(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    eve = _bearer(users["eve"])
    stop = app_client.post(BATCH, headers=eve, json={"items": [{"ref": "0x6040", "value": 0x06}]})
    assert stop.status_code == 200 and stop.json()["complete"], stop.text
    enable = {"items": [{"ref": "0x6040", "raw": 0x0F}], "verify": False}
    asked = app_client.post(BATCH, headers=eve, json=enable)
    assert asked.status_code == 428
    values = json.dumps(asked.json()["confirm_values"])
    assert app_client.post(BATCH, headers={**eve, "X-DriveBench-Confirm": str(MM)}, json=enable).status_code == 428
    both = {**eve, "X-DriveBench-Confirm": str(MM), "X-DriveBench-Confirm-Values": values}
    sent = app_client.post(BATCH, headers=both, json=enable)
    assert sent.status_code == 200, sent.text


def test_a_device_error_stops_the_batch_and_says_what_was_written(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    eve = _bearer(users["eve"])
    sim = _sim(app_client, MM)
    answer = app_client.post(BATCH, headers=eve, json={"items": [
        {"ref": "P1120", "value": 3.5}, {"ref": "0x2FFF.0", "value": "01"}, {"ref": "P1121", "value": 2.5}]})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert not body["complete"] and body["written"] == 1
    assert [(item["ref"], item["state"], item["ok"]) for item in body["items"]] == [
        ("P1120", "written", True), ("0x2FFF.0", "failed", False), ("P1121", "not sent", False)]
    error = body["items"][1]["error"]
    assert error["abort_code"] == "0x06020000" and "0x2FFF" in error["detail"]
    assert sim.store.get_ref("P1120") == 3.5 and sim.store.get_ref("P1121") != 2.5
    results = sorted((row["ref"], row["result"]) for row in _audit(app_client, eve))
    assert [ref for ref, _ in results] == ["0x2FFF", "P1120"] and results[1][1] == "written"
    assert results[0][1] != "written", "the failed write is logged with its outcome"


def test_the_lease_and_the_role_refuse_a_batch_before_anything_is_sent(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    root, eve, vera = (_bearer(users[name]) for name in ("root", "eve", "vera"))
    sim = _sim(app_client, MM)
    held = app_client.put(f"/api/sessions/{DEMO}/nodes/{MM}/parameters/P1120", headers=root, json={"value": 5})
    assert held.status_code == 200  # root now holds node 3's write lease
    leased = app_client.post(BATCH, headers=eve, json={"items": [{"ref": "P1121", "value": 7}]})
    assert leased.status_code == 409 and "root" in leased.text
    viewer = app_client.post(BATCH, headers=vera, json={"items": [{"ref": "P1121", "value": 7}]})
    assert viewer.status_code == 403 and "Writing parameters needs the engineer role" in viewer.json()["detail"]
    assert sim.store.get_ref("P1121") != 7
    assert [row["user"] for row in _audit(app_client, root)] == ["root"]
