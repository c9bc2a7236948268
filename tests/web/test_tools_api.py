"""Tools REST API: DIP-switch calculator, COB-IDs, cable and network planner, saved planned networks and their
comparison with a live scan of a simulated bus (Lenze nodes only, so the test does not depend on other profiles)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.web.app import create_app
from tests.conftest import fresh_channel

PLANT = {
    "name": "Tools test plant",
    "bus": "virtual:unused@500000",
    "nodes": [
        {"node_id": 5, "profile": "lenze-8400-motec-canopen", "name": "Conveyor"},
        {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib", "name": "Fan"},
    ],
}


@pytest.fixture
def api(app_db_url: str) -> Iterator[TestClient]:
    """The real app without any bus: the calculators and the database need none."""
    with TestClient(create_app()) as client:
        yield client


@pytest.fixture
def plant_api(tmp_path: Path, app_db_url: str) -> Iterator[TestClient]:
    """The real app with a simulated plant: an 8400 motec as node 5, an 8200 vector + EMF2178IB as node 12."""
    plant_file = tmp_path / "plant.json"
    plant_file.write_text(json.dumps(PLANT))
    app = create_app(plant_file=plant_file, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def session_id(api: TestClient) -> str:
    return str(api.get("/api/sessions").json()[0]["id"])


# --- calculators -------------------------------------------------------------------------------------------------
def test_dip_decode_manual_example_with_cob_ids(api: TestClient) -> None:
    """8400 motec §6.3.2: switches 16, 4, 2, 1 ON give node address 23."""
    body = api.get("/api/tools/dip/lenze-8400-motec", params={"on": "16,4,2,1,a"}).json()
    assert (body["result"]["node_id"], body["result"]["baud_kbit"]) == (23, 250)
    cob = {c["service"]: (c["hex"], c["cob_id"]) for c in body["cob_ids"]}
    assert cob["TPDO1"] == ("0x197", 0x197)
    assert cob["SDO1 rx"] == ("0x617", 0x617)
    assert cob["Heartbeat / boot-up"] == ("0x717", 0x717)
    assert cob["NMT"] == ("0x000", 0)
    assert any("§6.3.1" in text for text in body["family"]["ambiguities"])


def test_dip_post_switch_64_gives_63_and_lenze_rpdo2(api: TestClient) -> None:
    body = api.post("/api/tools/dip/lenze-8400-motec",
                    json={"switches": {"64": True, "1": True}, "pdo_ids": "lenze"}).json()
    assert (body["result"]["node_id"], body["result"]["address_switch_sum"]) == (63, 65)
    rpdo2 = next(c for c in body["cob_ids"] if c["service"] == "RPDO2")
    assert rpdo2["cob_id"] == 0x281 + 63


def test_dip_all_off_uses_the_codes(api: TestClient) -> None:
    body = api.post("/api/tools/dip/lenze-8400-motec", json={"switches": {}, "code_node_id": 9,
                                                              "code_baud_kbit": 125}).json()
    result = body["result"]
    assert (result["node_id"], result["node_id_source"], result["baud_kbit"], result["baud_source"]) == (
        9, "C00350", 125, "C00351")
    assert [(a["code"], a["value"]) for a in result["alternative"]] == [("C00350", 9), ("C00351", 2)]


def test_dip_encode_and_its_errors(api: TestClient) -> None:
    body = api.get("/api/tools/dip/lenze-emf2178ib", params={"node_id": 100, "baud_kbit": 10}).json()
    on = {k for k, v in body["result"]["switches"].items() if v}
    assert on == {"S1", "S2", "S5", "S8", "S9"}  # 64 + 32 + 4; S8 S9 ON, S10 OFF = 10 kbit/s
    bad = api.get("/api/tools/dip/lenze-8400-motec", params={"node_id": 64, "baud_kbit": 500})
    assert bad.status_code == 422
    assert bad.headers["content-type"].startswith("application/problem+json")
    assert "outside 1 … 63" in bad.json()["detail"]
    mixed = api.get("/api/tools/dip/lenze-8400-motec", params={"node_id": 3})
    assert mixed.status_code == 422
    assert api.get("/api/tools/dip/acme").status_code == 404
    mm4 = api.post("/api/tools/dip/siemens-mm4", json={"node_id": 4, "baud_kbit": 250}).json()
    assert {a["code"]: a["value"] for a in mm4["result"]["alternative"]} == {"P0918": 4, "P2010": 250,
                                                                             "P2041.04": 400}


def test_cobids_and_families(api: TestClient) -> None:
    families = api.get("/api/tools/dip").json()
    assert [f["key"] for f in families] == ["lenze-8400-motec", "lenze-emf2178ib", "siemens-mm4"]
    body = api.get("/api/tools/cobids", params={"family": "lenze-emf2178ib", "node_id": 10}).json()
    sdo2 = next(c for c in body["cob_ids"] if c["service"] == "SDO2 rx")
    assert (sdo2["cob_id"], sdo2["default_on"]) == (0x640 + 10, False)
    assert api.get("/api/tools/cobids", params={"family": "siemens-mm4", "node_id": 5,
                                               "pdo_ids": "lenze"}).status_code == 422


def test_cable_worked_example(api: TestClient) -> None:
    """8400 motec §5.2.4: 125 kbit/s, 0.5 mm², 28 nodes, 450 m -> one repeater after 360 m, 360 + 330 = 690 m."""
    body = api.get("/api/tools/cable", params={"baud_kbit": 125, "nodes": 28, "length_m": 450,
                                               "cross_section_mm2": 0.5}).json()
    assert (body["total_length_m"], body["segment_length_m"], body["repeaters"]) == (600, 360, 1)
    assert (body["segment_capacity_m"], body["feasible"]) == (690, True)
    tables = api.get("/api/tools/cable/tables").json()
    assert tables["selection_example"]["repeaters"] == [15, 6, 2, 1, 0, 0, 0]


def test_planner_check_finds_the_issue_examples(api: TestClient) -> None:
    plan = {"name": "bad", "nodes": [
        {"device": "lenze-8400-motec", "node_id": 3, "baud_kbit": 500},
        {"device": "lenze-8400-motec", "node_id": 3, "baud_kbit": 500},
        {"device": "lenze-emf2178ib", "node_id": 10, "baud_kbit": 500, "channels": ["pdo1", "sdo2"]},
        {"device": "lenze-8400-motec", "node_id": 20, "baud_kbit": 500, "pdo_ids": "lenze"},
        {"device": "lenze-8400-motec", "node_id": 21, "baud_kbit": 500},
        {"device": "siemens-mm4", "node_id": 74, "baud_kbit": 250},
        {"device": "lenze-8400-motec", "node_id": 100, "baud_kbit": 500},
    ]}
    report = api.post("/api/tools/planner/check", json=plan).json()
    kinds = {f["kind"] for f in report["findings"]}
    assert {"duplicate_node_id", "cob_id_collision", "mixed_baud", "out_of_range"} <= kinds
    collisions = [f for f in report["findings"] if f["kind"] == "cob_id_collision"]
    assert {f["cob_id"] for f in collisions} >= {0x640 + 10, 0x281 + 20}  # SDO2 = SDO1 of 74; RPDO2 = TPDO2 of 21
    assert not report["ok"]


# --- saved planned networks ----------------------------------------------------------------------------------------
PLAN = {"name": "Line 1", "nodes": [
    {"name": "Conveyor", "device": "lenze-8400-motec", "node_id": 5, "baud_kbit": 500},
    {"name": "Fan", "device": "lenze-emf2178ib", "node_id": 12, "baud_kbit": 500},
]}


def test_planned_network_crud_export_import(api: TestClient) -> None:
    assert api.get("/api/planned-networks").json() == []
    created = api.post("/api/planned-networks", json=PLAN)
    assert created.status_code == 201
    saved = created.json()
    assert saved["report"]["ok"] and saved["plan"]["nodes"][0]["node_id"] == 5
    network_id = saved["id"]

    changed = {**PLAN, "name": "Line 1 b", "nodes": [*PLAN["nodes"], {"device": "lenze-8400-motec", "node_id": 5,
                                                                       "baud_kbit": 500}]}
    updated = api.put(f"/api/planned-networks/{network_id}", json=changed).json()
    assert updated["name"] == "Line 1 b"
    assert [f["kind"] for f in updated["report"]["findings"]] == ["duplicate_node_id"]
    assert [(s["id"], s["node_count"]) for s in api.get("/api/planned-networks").json()] == [(network_id, 3)]

    exported = api.get(f"/api/planned-networks/{network_id}/export")
    assert exported.headers["content-disposition"] == 'attachment; filename="Line-1-b.json"'
    imported = api.post("/api/planned-networks/import", content=exported.content,
                        headers={"content-type": "application/json"})
    assert imported.status_code == 201
    assert imported.json()["plan"] == updated["plan"]

    bad = api.post("/api/planned-networks/import", content=b'{"name": "x", "nodes": [{"node_id": 1}]',
                   headers={"content-type": "application/json"})
    assert bad.status_code == 422
    assert "Not a network plan" in bad.json()["detail"]
    assert len(api.get("/api/planned-networks").json()) == 2  # nothing lost, nothing added

    assert api.delete(f"/api/planned-networks/{network_id}").status_code == 204
    assert api.get(f"/api/planned-networks/{network_id}").status_code == 404
    assert api.delete(f"/api/planned-networks/{network_id}").status_code == 404


def test_compare_saved_plan_with_a_live_scan(plant_api: TestClient) -> None:
    api = plant_api
    plan = {"name": "Line 1", "nodes": [
        {"name": "Conveyor", "device": "lenze-8400-motec", "node_id": 5, "baud_kbit": 500},
        {"name": "Fan", "device": "lenze-8400-motec", "node_id": 12, "baud_kbit": 500},  # really an EMF2178IB
        {"name": "Lift", "device": "lenze-8400-motec", "node_id": 9, "baud_kbit": 500},
    ]}
    network_id = api.post("/api/planned-networks", json=plan).json()["id"]
    response = api.post(f"/api/planned-networks/{network_id}/compare", params={"session": session_id(api)})
    assert response.status_code == 200, response.text
    result = response.json()
    assert {n["node_id"]: n["status"] for n in result["nodes"]} == {5: "ok", 12: "wrong_device", 9: "missing"}
    assert not result["ok"]

    fitting = {"name": "Only the conveyor", "nodes": [plan["nodes"][0]]}
    result = api.post("/api/tools/planner/compare", params={"session": session_id(api)}, json=fitting).json()
    assert {n["node_id"]: n["status"] for n in result["nodes"]} == {5: "ok", 12: "extra"}

    missing = api.post(f"/api/planned-networks/{network_id}/compare", params={"session": "nope"})
    assert missing.status_code == 404
    assert api.post("/api/planned-networks/999/compare", params={"session": session_id(api)}).status_code == 404


# --- the page's htmx endpoints -------------------------------------------------------------------------------------
def test_tools_page_renders_every_family(api: TestClient) -> None:
    page = api.get("/tools")
    assert page.status_code == 200
    assert page.text.count('class="dip-switch') == 10
    for family, switches in (("lenze-emf2178ib", 10), ("siemens-mm4", 0)):
        block = api.get("/ui/tools/dip", params={"family": family})
        assert block.status_code == 200
        assert block.text.count('class="dip-switch') == switches
    assert "P0918" in block.text and "P2010" in block.text


@pytest.mark.parametrize(("kbit", "value"), [(10, 0), (20, 100), (50, 200), (125, 300), (250, 400), (500, 500),
                                             (800, 600), (1000, 700)])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_tools_page_shows_the_whole_p2041_04_value(api: TestClient, kbit: int, value: int) -> None:
    """MICROMASTER §5.6 Table 5-1: the Value column holds the number to write (hundreds digit = baud rate, tens and
    ones = the factory communication-error reactions), not the hundreds digit alone."""
    block = api.post("/ui/tools/dip", data={"family": "siemens-mm4", "action": "encode", "node_id": "4",
                                            "baud_kbit": str(kbit)})
    assert block.status_code == 200
    row = re.search(r"<code>P2041\.04</code></td><td class=\"num\">([^<]*)</td>", block.text)
    assert row is not None and row.group(1) == str(value)


def test_ui_import_of_bad_json_reports_and_keeps_the_plan(api: TestClient) -> None:
    response = api.post("/ui/tools/planner/import", files={"plan_file": ("plan.json", b"{oops", "application/json")},
                        headers={"HX-Request": "true"})
    assert response.status_code == 422
    assert 'class="error"' in response.text and "Not a network plan" in response.text
    assert 'id="planner"' not in response.text  # the error goes beside the action; the plan is not replaced


def test_ui_save_then_load(api: TestClient) -> None:
    form = {"plan_name": "Hall", "row": ["0"], "device_0": "lenze-8400-motec", "node_id_0": "9", "baud_kbit_0": "250",
            "channels_0": ["pdo1"], "pdo_ids_0": "lenze"}
    saved = api.post("/ui/tools/planner/save", data=form)
    assert saved.status_code == 200 and "Saved &#39;Hall&#39;" in saved.text
    network_id = api.get("/api/planned-networks").json()[0]["id"]
    stored = api.get(f"/api/planned-networks/{network_id}").json()["plan"]["nodes"][0]
    assert (stored["node_id"], stored["baud_kbit"], stored["channels"], stored["pdo_ids"]) == (9, 250, ["pdo1"],
                                                                                                "lenze")
    loaded = api.post(f"/ui/tools/planner/load/{network_id}")
    assert 'value="Hall"' in loaded.text and f"saved as #{network_id}" in loaded.text


def test_ui_compare_shows_each_node(plant_api: TestClient) -> None:
    form = {"plan_name": "Line 1", "row": ["0", "1"], "device_0": "lenze-8400-motec", "node_id_0": "5",
            "baud_kbit_0": "500", "device_1": "lenze-emf2178ib", "node_id_1": "8", "baud_kbit_1": "500",
            "session_id": session_id(plant_api)}
    page = plant_api.post("/ui/tools/planner/compare", data=form)
    assert page.status_code == 200
    assert 'class="cmp-ok" data-node="5"' in page.text
    assert 'class="cmp-missing" data-node="8"' in page.text
    assert 'class="cmp-extra" data-node="12"' in page.text
    refused = plant_api.post("/ui/tools/planner/compare", data={**form, "session_id": "nope"},
                             headers={"HX-Request": "true"})
    assert refused.status_code == 404 and 'class="error"' in refused.text
