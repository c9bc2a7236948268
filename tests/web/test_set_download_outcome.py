"""A parameter-set download says what failed (issue 28 item 5, as a read-all does): a download, retry or rollback
whose writes failed ends "incomplete" ("failed" when nothing was written) in the job API and in the stored
download, with the counts written / verified / failed / not written, and each failed row says why. Through the
HTTP API on the demo plant (node 5: 8400 motec on a virtual CAN bus), the simulator's faults make the writes fail.
"""

from __future__ import annotations

import json
from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.web.test_parameter_sets_api import SESSION, SETS, finish, upload

NODE = f"/api/sessions/{SESSION}/nodes/5"
FAULTS = f"/api/sessions/{SESSION}/simulator/nodes/5/faults"
TARGET = {"session_id": SESSION, "node_id": 5}


def _faults(api: TestClient, **faults: Any) -> None:
    answer = api.put(FAULTS, json=faults)
    assert answer.status_code == 200, answer.text


def _changed_set(api: TestClient) -> int:
    """A set of node 5 whose C00039/1 (55 %) and C00088 (12.5 A) differ from what the node holds; the download
    writes C00039/1 first, then C00088."""
    set_id = upload(api, 5, "Conveyor")
    answer = api.patch(f"{SETS}/{set_id}", json={"values": {"C00039/1": 55.0, "C00088": 12.5}})
    assert answer.status_code == 200, answer.text
    return set_id


def _quick_sdo(api: TestClient) -> None:
    answer = api.put(f"/api/sessions/{SESSION}/sdo-settings", json={"timeout_s": 0.3, "retries": 1, "use_sdo2": False})
    assert answer.status_code == 200, answer.text


def _download(api: TestClient, set_id: int) -> dict[str, Any]:
    started = confirmed(api, "POST", f"{SETS}/{set_id}/download", json=TARGET)
    assert started.status_code == 202, started.text
    return finish(api, started.json(), 60)


def test_a_download_with_a_failed_write_ends_incomplete_and_says_which(demo_api: TestClient) -> None:
    set_id = _changed_set(demo_api)
    _quick_sdo(demo_api)
    _faults(demo_api, drop_downloads=2)  # C00039/1's write and its one retry go unanswered
    job = _download(demo_api, set_id)

    assert job["state"] == "incomplete" and job["download_state"] == "incomplete", job
    assert job["outcome"] == {"written": 1, "verified": 1, "failed": 1, "not_written": 0}, job["outcome"]
    assert job["progress"]["failed"] == 1 and job["progress"]["done"] == job["progress"]["total"]
    lines = {line["ref"]: line for line in job["report"]}
    assert lines["C00039/1"]["status"] == "failed" and lines["C00039/1"]["detail"], lines["C00039/1"]
    assert lines["C00088"]["status"] == "written"

    stored = demo_api.get(f"/api/parameter-downloads/{job['download_id']}").json()
    assert stored["state"] == "incomplete"
    assert stored["outcome"] == {"written": 1, "verified": 1, "failed": 1, "not_written": 0}, stored

    _faults(demo_api)  # the node answers again: the retry writes what failed and ends done
    retried = finish(demo_api, confirmed(demo_api, "POST",
                                         f"/api/parameter-downloads/{job['download_id']}/retry").json(), 60)
    assert retried["state"] == "done" and retried["outcome"]["verified"] == 1, retried


def test_a_download_that_wrote_nothing_ends_failed(demo_api: TestClient) -> None:
    set_id = _changed_set(demo_api)
    _quick_sdo(demo_api)
    _faults(demo_api, drop_downloads=100)  # no write is answered; reads are
    job = _download(demo_api, set_id)

    assert job["state"] == "failed" and job["download_state"] == "failed", job
    assert job["outcome"]["written"] == 0 and job["outcome"]["failed"] + job["outcome"]["not_written"] == 2, job
    assert "nothing was written" in (job["error"] or "").lower(), job
    assert all(line["detail"] for line in job["report"] if line["status"] != "unchanged"), job["report"]


def test_a_rollback_with_a_failed_write_ends_incomplete(demo_api: TestClient) -> None:
    set_id = _changed_set(demo_api)
    job = _download(demo_api, set_id)
    assert job["state"] == "done" and job["outcome"] == {"written": 2, "verified": 2, "failed": 0, "not_written": 0}

    _quick_sdo(demo_api)
    _faults(demo_api, drop_downloads=2)  # the rollback's first write goes unanswered
    back = finish(demo_api, confirmed(demo_api, "POST",
                                      f"/api/parameter-downloads/{job['download_id']}/rollback").json(), 60)
    assert back["state"] == "incomplete" and back["download_state"] == "incomplete", back
    assert back["outcome"] == {"written": 1, "verified": 1, "failed": 1, "not_written": 0}, back["outcome"]
    assert json.dumps(back["report"]).count('"failed"') == 1
