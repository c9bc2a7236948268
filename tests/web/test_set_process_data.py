"""An upload leaves out what the manuals call process data (issue 28 item 1 for the 8400 motec family): the CAN
input words C00866/1...8 and CAN1_IN words C00876/1...4 of the 8400 motec CANopen unit (node 5 of the demo plant,
virtual CAN bus), the process data input words C00876/1...2 of the 8400 motec EtherCAT unit (station 1001 behind
the demo plant's simulated mailbox gateway); the job's note names each. Through the HTTP API."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.web.test_parameter_sets_api import SETS, finish

CANOPEN = ("demo-plant", 5, [f"C00866/{n}" for n in range(1, 9)] + [f"C00876/{n}" for n in range(1, 5)])
ETHERCAT = ("ethercat-line", 1, ["C00876/1", "C00876/2"])


@pytest.mark.parametrize(("session", "node", "process_data"), [CANOPEN, ETHERCAT], ids=["canopen", "ethercat"])
def test_an_upload_leaves_out_the_process_data_words_and_says_which(
        demo_api: TestClient, session: str, node: int, process_data: list[str]) -> None:
    started = demo_api.post(f"{SETS}/upload", json={"session_id": session, "node_id": node, "name": "All"})
    assert started.status_code == 202, started.text
    job = finish(demo_api, started.json(), 120)
    assert job["state"] == "done", job
    stored = {value["ref"] for value in demo_api.get(f"{SETS}/{job['set_id']}").json()["values"]}
    assert stored and not stored & set(process_data), sorted(stored & set(process_data))
    note = next(note for note in job["notes"] if "process data" in note)
    named = {ref.strip() for ref in note.split(":", 1)[1].split(",")}
    assert set(process_data) <= named, note
    assert "C00039/1" in stored and "C00039/1" not in named  # a setting stays
