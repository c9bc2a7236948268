"""Plant page actions through the real app (htmx requests, HTML answers)."""

from __future__ import annotations

from fastapi.testclient import TestClient

HTMX = {"HX-Request": "true"}


def test_adding_a_node_that_is_there_already_is_refused_not_replaced(client: TestClient) -> None:
    answer = client.post("/ui/sessions/demo-plant/nodes", data={"node_id": "3", "profile_id": ""}, headers=HTMX)
    assert answer.status_code == 409
    assert "Node 3 is already in session" in answer.text and "Pump (MICROMASTER 440)" in answer.text
    nodes = client.get("/api/sessions/demo-plant/nodes").json()
    assert next(n for n in nodes if n["node_id"] == 3)["device"] == "Pump (MICROMASTER 440)"  # profile kept


def test_adding_a_new_node_lists_it(client: TestClient) -> None:
    answer = client.post("/ui/sessions/demo-plant/nodes", data={"node_id": "40", "profile_id": ""}, headers=HTMX)
    assert answer.status_code == 200
    assert 'id="node-demo-plant-40"' in answer.text
