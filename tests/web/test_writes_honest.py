"""Every write the tool sends is in the audit log with the screen it came from, and a write whose answer was lost
says so (issue 28 items 3 and 4): through the HTTP API on the demo plant (virtual CAN bus, simulated nodes, the
simulator's fault injection).

Node 3 MICROMASTER 440 (CiA 402 panel), node 5 8400 motec (a second SDO channel, 0x1201), node 12 8200 vector."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.device.profiles.scaling import to_raw
from tests.confirming import confirmed
from tests.conftest import wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

SESSION = "demo-plant"
NODE = f"/api/sessions/{SESSION}/nodes"
FAULTS = f"/api/sessions/{SESSION}/simulator/nodes/{{node}}/faults"


def _audit(api: TestClient, node: int) -> list[dict[str, Any]]:
    answer = api.get("/api/audit", params={"node_id": node})
    assert answer.status_code == 200, answer.text
    rows: list[dict[str, Any]] = answer.json()
    return rows


def _store(api: TestClient, node: int) -> Any:
    return api.app.state.drivebench.plants[SESSION].nodes[node].store  # type: ignore[attr-defined]


def _faults(api: TestClient, node: int, **faults: Any) -> None:
    assert api.put(FAULTS.format(node=node), json=faults).status_code == 200


def _quick_sdo(api: TestClient) -> None:
    assert api.put(f"/api/sessions/{SESSION}/sdo-settings",
                   json={"timeout_s": 0.3, "retries": 1, "use_sdo2": False}).status_code == 200


def test_a_write_whose_answer_was_lost_says_the_outcome_is_unknown_and_what_the_device_holds(
        demo_api: TestClient) -> None:
    """The drive writes the value, its answer never arrives (both tries): not "did not answer" as if nothing had
    happened, but 504 "outcome unknown" with the value read back, and the audit row says unknown with it."""
    _quick_sdo(demo_api)
    before = demo_api.get(f"{NODE}/5/parameters/C00088").json()["display"]
    assert before != "12.50 A"
    _faults(demo_api, 5, lost_download_answers=2)  # the write and its one retry

    answer = demo_api.put(f"{NODE}/5/parameters/C00088", json={"value": "12.5"})
    assert answer.status_code == 504, answer.text
    assert answer.headers["content-type"] == "application/problem+json"
    problem = answer.json()
    assert "unknown" in problem["detail"] and "12.50 A" in problem["detail"], problem
    assert problem["read_back"] == "12.50 A" and problem["outcome"] == "unknown"
    assert "did not answer" not in problem["detail"]
    assert _store(demo_api, 5).get_ref("C00088") == 1250  # the device did apply it

    row = _audit(demo_api, 5)[0]
    assert (row["ref"], row["result"], row["origin"]) == ("C00088", "unknown", "parameters"), row
    assert "12.50 A" in row["detail"], row


def test_a_lost_answer_whose_read_back_fails_too_says_so(demo_api: TestClient) -> None:
    """The answer lost and every answer of the node too late for the read-back: the outcome is unknown and nothing
    could be read back."""
    _quick_sdo(demo_api)
    _faults(demo_api, 5, lost_download_answers=2, latency_ms=900)
    answer = demo_api.put(f"{NODE}/5/parameters/C00088", json={"value": "13.5"})
    assert answer.status_code == 504, answer.text
    problem = answer.json()
    assert problem["outcome"] == "unknown" and "read_back" not in problem, problem  # nothing read
    assert "unknown" in problem["detail"] and "could not be read back" in problem["detail"], problem
    row = _audit(demo_api, 5)[0]
    assert row["result"] == "unknown" and "could not be read back" in row["detail"], row


def test_pdo_apply_heartbeat_and_sdo2_switch_on_are_in_the_audit_log(demo_api: TestClient) -> None:
    report = demo_api.put(f"{NODE}/3/pdos/tpdo/5", json={"entries": [[0x6041, 0], [0x2803, 3]],
                                                         "transmission_type": 255})
    assert report.status_code == 200 and report.json()["ok"], report.text
    steps = report.json()["steps"]
    pdo_rows = [row for row in _audit(demo_api, 3) if row["origin"] == "pdo"]
    assert len(pdo_rows) == len(steps) >= 5
    assert [row["address"] for row in reversed(pdo_rows)] == [
        f"0x{s['index']:04X}sub{s['subindex']}" for s in steps]
    assert {row["result"] for row in pdo_rows} == {"not verified"}

    producer = demo_api.put(f"{NODE}/5/heartbeat/producer", json={"time_ms": 200})
    assert producer.status_code == 200, producer.text
    heartbeat = [row for row in _audit(demo_api, 5) if row["origin"] == "diagnostics"]
    assert len(heartbeat) == 1 and heartbeat[0]["address"] == "0x1017sub0", heartbeat
    assert heartbeat[0]["new_value"].startswith("200") and heartbeat[0]["result"] == "written", heartbeat

    _store(demo_api, 5).set(0x1201, 1, 0x80000000)  # SDO2 off: the read-all switches it on
    started = demo_api.post(f"{NODE}/5/read-all", json={})
    assert started.status_code == 202, started.text
    job = started.json()
    assert wait_until(lambda: demo_api.get(f"/api/jobs/{job['id']}").json()["state"] != "running", 120)
    sdo2 = [row for row in _audit(demo_api, 5) if row["origin"] == "read-all"]
    assert sorted(row["address"] for row in sdo2) == ["0x1201sub1", "0x1201sub2"], sdo2
    assert {row["result"] for row in sdo2} == {"written"}, sdo2


def test_the_sdo2_switch_on_of_a_set_upload_is_the_uploads(demo_api: TestClient) -> None:
    _store(demo_api, 5).set(0x1201, 1, 0x80000000)  # SDO2 off: reading node 5 into a set switches it on
    started = demo_api.post("/api/parameter-sets/upload", json={"session_id": SESSION, "node_id": 5, "name": "N5"})
    assert started.status_code == 202, started.text
    job = started.json()
    assert wait_until(lambda: demo_api.get(f"/api/parameter-sets/jobs/{job['id']}").json()["state"] != "running",
                      120)
    sdo2 = [row for row in _audit(demo_api, 5) if row["address"].startswith("0x1201")]
    assert sorted((row["address"], row["origin"]) for row in sdo2) == [("0x1201sub1", "upload"),
                                                                      ("0x1201sub2", "upload")], sdo2


def test_control_panel_writes_are_logged_as_control(demo_api: TestClient) -> None:
    store = _store(demo_api, 3)
    for ref in ("P0700", "P1000"):  # the MICROMASTER takes commands and setpoint from the bus
        store.set_ref(ref, to_raw(store.catalog.resolve(ref).entry, 6))
    control = f"{NODE}/3/control"
    assert wait_until(lambda: demo_api.get(control).json()["state"] == "switch_on_disabled", 8)
    assert demo_api.post(f"{control}/commands/shutdown").json()["state"] == "ready"
    assert demo_api.post(f"{control}/commands/switch_on").json()["state"] == "switched_on"
    assert confirmed(demo_api, "POST", f"{control}/commands/enable_operation").status_code == 200
    assert confirmed(demo_api, "PUT", f"{control}/setpoint", json={"value": 200}).status_code == 200
    assert demo_api.post(f"{control}/commands/shutdown").status_code == 200

    rows = _audit(demo_api, 3)
    assert rows and {row["origin"] for row in rows} == {"control"}, rows
    assert len([row for row in rows if row["address"] == "0x6040sub0"]) >= 4
    written = demo_api.put(f"{NODE}/3/parameters/P1082", json={"value": "50"})  # the Parameters tab stays
    assert written.status_code == 200, written.text
    assert _audit(demo_api, 3)[0]["origin"] == "parameters"
