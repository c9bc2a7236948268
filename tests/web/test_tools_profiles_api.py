"""The network planner, the COB-ID table and the cable check for devices without DIP switches (issue 30 item 7):
node 7's generic CiA 402 servo, an EDS uploaded through the real API, and the EtherCAT unit, which is on no CAN line.

Everything comes from the profiles: the servo's bit rates (features), the EDS's ``[DeviceInfo] BaudRate_xxx`` and
the default COB-IDs of their communication objects (``$NODEID+0x80000300``: RPDO2 off in the factory setting)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.web.app import create_app

SERVO = "generic-cia402-servo"
EDS = Path(__file__).resolve().parents[1] / "data" / "eds" / "cia402_servo.eds"
"""EM-Servo 400: BaudRate_125/250/500/1000 = 1 (800 = 0), 2 RPDOs and 2 TPDOs."""


@pytest.fixture
def uploaded(user_dir: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[TestClient, str]]:
    """The app with the EDS uploaded over POST /api/profiles; yields the client and the new profile's id."""
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as api:
        response = api.post("/api/profiles", files={"file": ("em-servo.eds", EDS.read_bytes())})
        assert response.status_code == 201, response.text
        yield api, response.json()["id"]


def check(api: TestClient, *nodes: dict[str, Any], cable_m: float | None = None) -> dict[str, Any]:
    plan: dict[str, Any] = {"name": "Line 3", "nodes": list(nodes)}
    if cable_m is not None:
        plan["cable"] = {"length_m": cable_m}
    response = api.post("/api/tools/planner/check", json=plan)
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_a_line_with_node_7_and_an_uploaded_eds_is_planned_with_cob_ids_and_cable(
        uploaded: tuple[TestClient, str]) -> None:
    api, eds_id = uploaded
    report = check(api, {"name": "Axis", "device": SERVO, "node_id": 7, "baud_kbit": 500},
                   {"name": "Press", "device": eds_id, "node_id": 8, "baud_kbit": 500},
                   {"name": "Conveyor", "device": "lenze-8400-motec", "node_id": 5, "baud_kbit": 500}, cable_m=80)
    assert report["findings"] == [] and report["ok"]
    used = {(row["node_id"], row["service"]): row["hex"] for row in report["cob_table"]}
    assert (used[(7, "TPDO1")], used[(7, "RPDO3")], used[(7, "SDO1 rx")], used[(7, "EMCY")]) == (
        "0x187", "0x407", "0x607", "0x087")
    assert (used[(8, "TPDO2")], used[(8, "SDO1 tx")], used[(8, "Heartbeat / boot-up")]) == ("0x288", "0x588", "0x708")
    assert (7, "TPDO3") not in used  # 0x1802sub1 = $NODEID+0x80000380: not valid in the factory setting
    assert (report["cable"]["baud_kbit"], report["cable"]["nodes"], report["cable"]["feasible"]) == (500, 3, True)

    too_long = check(api, {"device": SERVO, "node_id": 7, "baud_kbit": 500},
                     {"device": eds_id, "node_id": 8, "baud_kbit": 500}, cable_m=150)
    assert [(f["kind"], f["severity"]) for f in too_long["findings"]] == [("cable", "error")]
    assert "150 m is too long at 500 kbit/s (max. 113 m)" in too_long["findings"][0]["message"]


def test_the_profiles_bit_rates_and_cob_ids_are_checked(uploaded: tuple[TestClient, str]) -> None:
    api, eds_id = uploaded
    report = check(api, {"device": SERVO, "node_id": 7, "baud_kbit": 20},
                   {"device": eds_id, "node_id": 8, "baud_kbit": 800})
    rates = {f["node_ids"][0]: f["message"] for f in report["findings"] if f["kind"] == "unsupported_baud"}
    assert "does not support 20 kbit/s (125, 250, 500, 800, 1000)" in rates[7]
    assert "EM-Servo 400 does not support 800 kbit/s (125, 250, 500, 1000)" in rates[8]  # BaudRate_800=0

    # the 8400 motec's SDO2 (0x640 + 5) is the EDS node 69's SDO1 request identifier
    clash = check(api, {"device": "lenze-8400-motec", "node_id": 5, "baud_kbit": 250, "channels": ["pdo1", "sdo2"]},
                  {"device": eds_id, "node_id": 69, "baud_kbit": 250})
    collisions = {f["cob_id"]: f for f in clash["findings"] if f["kind"] == "cob_id_collision"}
    assert sorted(collisions) == [0x5C5, 0x645] and collisions[0x645]["node_ids"] == [5, 69]
    assert "SDO2 rx of node 5 and SDO1 rx of node 69" in collisions[0x645]["message"]

    servo_only = check(api, {"device": SERVO, "node_id": 7, "baud_kbit": 500, "channels": ["tpdo1", "pdo4"]})
    assert [f["kind"] for f in servo_only["findings"]] == ["unknown_channel"]
    channels = "(tpdo1, rpdo1, tpdo2, rpdo2, tpdo3, rpdo3, sdo1)"
    assert f"has no channel(s) pdo4 {channels}" in servo_only["findings"][0]["message"]


def test_cob_id_table_of_node_7_and_of_the_eds(uploaded: tuple[TestClient, str]) -> None:
    api, eds_id = uploaded
    servo = api.get("/api/tools/cobids", params={"family": SERVO, "node_id": 7}).json()
    rows = {c["service"]: c for c in servo["cob_ids"]}
    assert (rows["TPDO1"]["hex"], rows["TPDO1"]["source"]) == ("0x187", "default of 0x1800sub1")
    assert (rows["TPDO3"]["hex"], rows["TPDO3"]["default_on"]) == ("0x387", False)
    assert rows["SYNC"]["cob_id"] == 0x80 and not rows["SYNC"]["node_specific"]
    assert any("BaudRate_xxx" in note for note in servo["notes"])

    eds = {c["service"]: c for c in api.get("/api/tools/cobids", params={"family": eds_id, "node_id": 8}).json()[
        "cob_ids"]}
    assert (eds["RPDO2"]["hex"], eds["RPDO2"]["default_on"]) == ("0x308", False)  # $NODEID+0x80000300
    assert (eds["SDO1 tx"]["hex"], eds["SDO1 tx"]["source"]) == ("0x588", "default of 0x1200sub2")


def test_the_ethercat_unit_is_not_planned_on_a_can_line_and_says_why(uploaded: tuple[TestClient, str]) -> None:
    api, _eds_id = uploaded
    report = check(api, {"name": "Gate", "device": "lenze-8400-motec-ethercat", "node_id": 3, "baud_kbit": 500})
    [finding] = report["findings"]
    assert (finding["kind"], finding["severity"], report["ok"]) == ("not_canopen", "error", False)
    assert "EtherCAT has no node id, bit rate or COB-ID plan" in finding["message"]
    refused = api.get("/api/tools/cobids", params={"family": "lenze-8400-motec-ethercat", "node_id": 3})
    assert refused.status_code == 422
    assert "is an EtherCAT slave: EtherCAT has no node id, bit rate or COB-ID plan" in refused.json()["detail"]


def test_a_profile_without_switches_has_no_dip_calculator_and_the_answer_says_so(
        uploaded: tuple[TestClient, str]) -> None:
    api, eds_id = uploaded
    assert SERVO not in [f["key"] for f in api.get("/api/tools/dip").json()]
    for name in (SERVO, eds_id):
        refused = api.get(f"/api/tools/dip/{name}", params={"on": ""})
        assert refused.status_code == 422
        assert "has no DIP-switch calculator: its profile has no 'switches' section" in refused.json()["detail"]
    page = api.get("/tools").text
    assert "No DIP-switch calculator for" in page and "EM-Servo 400" in page
    assert f'<option value="{SERVO}"' in page and f'<option value="{eds_id}"' in page
    assert "Not on a CAN line" in page


def test_a_saved_plan_with_node_7_matches_a_scan_of_the_demo_plant(demo_api: TestClient) -> None:
    """The real simulator on a virtual bus: node 7 answers with the generic servo's identity, node 3 (a MICROMASTER)
    is not the servo the plan says."""
    saved = demo_api.post("/api/planned-networks", json={"name": "Demo line", "nodes": [
        {"name": "Axis", "device": SERVO, "node_id": 7, "baud_kbit": 500},
        {"name": "Pump", "device": "siemens-mm4", "node_id": 3, "baud_kbit": 500},
        {"name": "Wrong", "device": SERVO, "node_id": 5, "baud_kbit": 500}]})
    assert saved.status_code == 201, saved.text
    assert saved.json()["report"]["ok"]
    result = demo_api.post(f"/api/planned-networks/{saved.json()['id']}/compare",
                           params={"session": "demo-plant", "timeout_s": 2}).json()
    status = {node["node_id"]: node["status"] for node in result["nodes"]}
    assert (status[7], status[3], status[5]) == ("ok", "ok", "wrong_device")
    assert status[12] == "extra"
