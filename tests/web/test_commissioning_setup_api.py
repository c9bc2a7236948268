"""Guided commissioning by profile data alone (issue 30 item 3) over the real HTTP API on the demo plant: node 7
(a CiA 402 servo whose profile has no commissioning section) gets the generic CiA 402 set-up built from its
standard objects, and the EtherCAT unit its profile's sequence over the CoE mailbox, each step the checked write
read back and the enable step confirmed."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed

SERVO = "/api/sessions/demo-plant/nodes/7/control"
UNIT = "/api/sessions/ethercat-line/nodes/1/control"


def _walk(api: TestClient, base: str, run: dict[str, Any], values: dict[str, object]) -> dict[str, Any]:
    while not run["finished"]:
        step = run["steps"][run["position"]]
        body = {"value": values[step["field"]["ref"]]} if step["field"] and step["field"]["ref"] in values else {}
        answer = confirmed(api, "POST", f"{base}/runs/{run['id']}/next", json=body)
        assert answer.status_code == 200, answer.text
        run = answer.json()
        api.post(f"{base}/keepalive")
    return run


def test_the_servo_is_offered_the_cia402_set_up_with_form_fields(demo_api: TestClient) -> None:
    sequences = demo_api.get(f"{SERVO}/sequences").json()
    assert [seq["key"] for seq in sequences] == ["cia402-setup"]
    assert "0x6080" in sequences[0]["missing"][0]
    run = demo_api.post(f"{SERVO}/sequences/cia402-setup/runs").json()
    fields = {step["field"]["ref"]: step["field"] for step in run["steps"]}
    assert fields["0x6083"]["proposal"] == 3000 and fields["0x6098"]["name"] == "Homing method"
    assert "Profile position" in (run["steps"][0]["note"] or "")
    run = _walk(demo_api, SERVO, run, {"0x6084": 4500, "0x6098": 35})
    assert run["failed"] is None and all(result["ok"] for result in run["results"]), run["results"]
    assert demo_api.get("/api/sessions/demo-plant/nodes/7/parameters/0x6084").json()["raw"] == 4500
    audit = demo_api.get("/api/audit", params={"node_id": 7}).json()
    rows = audit["items"] if isinstance(audit, dict) else audit
    assert {"0x6084", "0x6098"} <= {row["ref"] for row in rows if row["origin"] == "commissioning"}


def test_the_ethercat_unit_runs_its_profiles_sequence_over_coe(demo_api: TestClient) -> None:
    sequences = demo_api.get(f"{UNIT}/sequences").json()
    assert [seq["key"] for seq in sequences] == ["l8400-ethercat"]
    run = demo_api.post(f"{UNIT}/sequences/l8400-ethercat/runs").json()
    enable = next(step for step in run["steps"] if step["title"].startswith("C00876/1 = 0x0009"))
    assert enable["moves"]
    while run["steps"][run["position"]]["number"] < enable["number"]:
        run = _walk_one(demo_api, run)
    refused = demo_api.post(f"{UNIT}/runs/{run['id']}/next", json={})
    assert refused.status_code == 428 and refused.json()["confirm_node"] == 1, refused.text
    run = _walk(demo_api, UNIT, run, {})
    assert run["failed"] is None and all(result["ok"] for result in run["results"]), run["results"]
    assert demo_api.get(f"{UNIT}").json()["state"] == "ready"


def _walk_one(api: TestClient, run: dict[str, Any]) -> dict[str, Any]:
    answer = confirmed(api, "POST", f"{UNIT}/runs/{run['id']}/next", json={})
    assert answer.status_code == 200, answer.text
    result: dict[str, Any] = answer.json()
    return result
