"""A retry and a rollback ask only about the moving values they change (issue 28 item 2, as a set download does):
they read what the node holds first, like the download. Through the HTTP API on the demo plant (node 12: 8200
vector + EMF2178IB on a virtual CAN bus; C0001, the setpoint source, can make the drive move)."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.web.test_parameter_sets_api import SESSION, SETS, finish, upload

NODE = f"/api/sessions/{SESSION}/nodes/12"
TARGET = {"session_id": SESSION, "node_id": 12}


def _download(api: TestClient, values: dict[str, Any]) -> dict[str, Any]:
    set_id = upload(api, 12, "Fan")
    assert api.patch(f"{SETS}/{set_id}", json={"values": values}).status_code == 200
    started = confirmed(api, "POST", f"{SETS}/{set_id}/download", json=TARGET)
    assert started.status_code == 202, started.text
    return finish(api, started.json(), 60)


def _held(api: TestClient, ref: str) -> Any:
    answer = api.get(f"{NODE}/parameters/{ref}")
    assert answer.status_code == 200, answer.text
    return answer.json()["value"]


def test_a_rollback_asks_only_about_the_moving_values_it_changes(demo_api: TestClient) -> None:
    before = _held(demo_api, "C0001")
    job = _download(demo_api, {"C0001": 1 if before != 1 else 2, "C0012": 7.5})
    assert job["state"] == "done", job
    rollback = f"/api/parameter-downloads/{job['download_id']}/rollback"

    asked = demo_api.post(rollback)  # C0001 goes back: the rollback names it, and only it
    assert asked.status_code == 428, asked.text
    assert asked.json()["confirm_values"] and all(key.startswith("C0001") for key in asked.json()["confirm_values"])

    back = confirmed(demo_api, "PUT", f"{NODE}/parameters/C0001", json={"value": before})  # someone set it back
    assert back.status_code == 200, back.text
    started = demo_api.post(rollback)  # nothing that moves changes now: nothing to ask
    assert started.status_code == 202, started.text
    done = finish(demo_api, started.json(), 60)
    statuses = {line["ref"]: line["status"] for line in done["report"]}
    assert statuses == {"C0001": "unchanged", "C0012": "written"}, statuses


def test_a_retry_asks_only_about_the_moving_values_it_changes(demo_api: TestClient) -> None:
    """C0001's write is applied but its answer lost (the simulator's lost_download_answers): the download reports it
    failed; the node holds the set's value, so the retry changes nothing that moves and asks nothing."""
    assert demo_api.put(f"/api/sessions/{SESSION}/sdo-settings",
                        json={"timeout_s": 0.3, "retries": 1, "use_sdo2": False}).status_code == 200
    target = 1 if _held(demo_api, "C0001") != 1 else 2
    set_id = upload(demo_api, 12, "Fan")
    assert demo_api.patch(f"{SETS}/{set_id}", json={"values": {"C0001": target}}).status_code == 200
    assert demo_api.put(f"/api/sessions/{SESSION}/simulator/nodes/12/faults",
                        json={"lost_download_answers": 2}).status_code == 200
    job = finish(demo_api, confirmed(demo_api, "POST", f"{SETS}/{set_id}/download", json=TARGET).json(), 60)
    assert {line["ref"]: line["status"] for line in job["report"] if line["status"] != "unchanged"} == \
        {"C0001": "failed"}, job["report"]
    assert _held(demo_api, "C0001") == target

    started = demo_api.post(f"/api/parameter-downloads/{job['download_id']}/retry")
    assert started.status_code == 202, started.text
    retried = finish(demo_api, started.json(), 60)
    assert retried["state"] == "done" and [line["status"] for line in retried["report"]] == ["unchanged"], retried
