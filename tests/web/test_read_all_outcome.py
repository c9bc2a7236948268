"""A read-all says what it could not read (issue 28 item 5): the job ends "incomplete" with the counts of items
failed and not read, and each parameter it could not read says why; over the HTTP API on the demo plant."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.conftest import wait_for_value

DEMO = "/api/sessions/demo-plant"


def _finished(client: TestClient, job_id: str) -> dict[str, Any]:
    def ended() -> dict[str, Any] | None:
        job: dict[str, Any] = client.get(f"/api/jobs/{job_id}").json()
        return job if job["state"] != "running" else None
    return wait_for_value(ended, 120, "the read-all ends")


def _listed(client: TestClient, node: int, q: str) -> dict[str, Any]:
    found: dict[str, Any] = client.get(f"{DEMO}/nodes/{node}/parameters", params={"q": q}).json()
    return found["parameters"][0]


def test_a_node_that_does_not_answer_ends_incomplete_with_what_was_not_read(client: TestClient) -> None:
    added = client.post(f"{DEMO}/nodes", json={"node_id": 20, "profile_id": "generic-cia402-servo"})
    assert added.status_code == 201, added.text
    job = _finished(client, client.post(f"{DEMO}/nodes/20/read-all").json()["id"])
    progress = job["progress"]
    assert job["state"] == "incomplete", job
    assert progress["not_done"] > 0 and progress["failed"] > 0
    assert progress["done"] == progress["total"] and progress["failed"] + progress["not_done"] == progress["total"]
    assert "not read" in _listed(client, 20, "0x6041")["read_failed"]


def test_the_object_that_failed_is_marked(client: TestClient) -> None:
    job = _finished(client, client.post(f"{DEMO}/nodes/3/read-all").json()["id"])
    assert job["state"] == "incomplete" and job["progress"]["failed"] >= 1 and job["progress"]["not_done"] == 0
    failed = _listed(client, 3, "0x1008")
    assert failed["last"] is None and failed["read_failed"], failed
    read = _listed(client, 3, "0x1000")
    assert read["last"] is not None and read["read_failed"] is None
