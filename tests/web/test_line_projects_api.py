"""Line projects through the real HTTP API (issue 32): made from a planned network and a parameter set, exported
as JSON and lely YAML, opened on a FRESH server and database (the planned network and the set come back), a broken
file named with its line (nothing stored), the boot-up check against the demo plant, and a concise DCF downloaded
entry by entry to a simulated drive and read back."""

from __future__ import annotations

import base64
import contextlib
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from fastapi.testclient import TestClient

from drivebench.config import settings as app_settings
from drivebench.services.storage import database
from drivebench.web.app import create_app
from tests.concise_dcf_reader import read_concise_dcf
from tests.confirming import confirmed

SESSION = "demo-plant"
PLAN = {"name": "Line 4", "nodes": [
    {"name": "Conveyor", "device": "lenze-8400-motec-canopen", "node_id": 5, "baud_kbit": 500},
    {"name": "Axis", "device": "generic-cia402-servo", "node_id": 7, "baud_kbit": 500},
    {"name": "Fan", "device": "lenze-8200-vector-emf2178ib", "node_id": 12, "baud_kbit": 500}]}
AXIS_SET = {"schema": "drivebench.parameter-set/1", "name": "Axis set", "profile_id": "generic-cia402-servo",
            "parameters": [{"ref": "0x1800.3", "value": 250}, {"ref": "0x1801.5", "value": 40},
                           {"ref": "0x605A", "value": 5}]}


def make_project(api: TestClient) -> dict[str, Any]:
    network = api.post("/api/planned-networks", json=PLAN)
    assert network.status_code == 201, network.text
    imported = api.post("/api/parameter-sets/import",
                        files={"file": ("axis.json", json.dumps(AXIS_SET).encode(), "application/json")})
    assert imported.status_code == 201, imported.text
    made = api.post("/api/line-projects", json={"network_id": network.json()["id"],
                                                "sets": {"7": imported.json()["set"]["id"]}, "optional": [12]})
    assert made.status_code == 201, made.text
    return dict(made.json())


@contextlib.contextmanager
def fresh_server(tmp_path: Path) -> Iterator[TestClient]:
    """A second server with a database of its own and no plant. The app reads the database address at each
    request: the first server's database is back once this one is closed."""
    first, url = app_settings.database_url, f"sqlite:///{tmp_path / 'fresh.db'}"
    app_settings.database_url = url
    try:
        with TestClient(create_app()) as client:
            yield client
    finally:
        app_settings.database_url = first
        database.dispose(url)


def test_project_holds_identity_profile_set_and_pdo_in_a_stable_order(demo_api: TestClient) -> None:
    project = make_project(demo_api)["project"]
    assert [node["node_id"] for node in project["nodes"]] == [5, 7, 12]
    axis = project["nodes"][1]
    assert axis["identity"]["product_code"] == "0x00402001" and axis["identity"]["revision_min"] == "0x00010000"
    assert axis["profile"]["id"] == "generic-cia402-servo" and len(axis["profile"]["sha256"]) == 64
    assert axis["profile"]["embedded"] is None  # built in: named, not carried
    assert axis["parameter_set"]["values"] == {"0x605A": 5}
    assert axis["pdo"] == {"0x1800.3": 250, "0x1801.5": 40}
    assert [node["mandatory"] for node in project["nodes"]] == [True, True, False]
    text = demo_api.get(f"/api/line-projects/{make_project(demo_api)['id']}/export").text
    assert list(json.loads(text)) == ["schema_version", "name", "master", "cable", "nodes"]
    assert text.index('"node_id": 5') < text.index('"node_id": 7') < text.index('"node_id": 12')


@pytest.mark.parametrize("fmt", ["json", "yaml"])
def test_export_then_open_on_a_fresh_server_recreates_network_and_sets(demo_api: TestClient, tmp_path: Path,
                                                                       fmt: str) -> None:
    made = make_project(demo_api)
    exported = demo_api.get(f"/api/line-projects/{made['id']}/export", params={"format": fmt})
    assert exported.status_code == 200
    assert exported.headers["content-disposition"] == f'attachment; filename="Line-4.{fmt}"'
    with fresh_server(tmp_path) as fresh:
        assert fresh.get("/api/planned-networks").json() == []
        opened = fresh.post("/api/line-projects/import", params={"filename": f"line-4.{fmt}"},
                            content=exported.content)
        assert opened.status_code == 201, opened.text
        body = opened.json()
        assert body["notes"] == []
        network = fresh.get(f"/api/planned-networks/{body['network_id']}").json()
        assert [(n["node_id"], n["device"], n["name"]) for n in network["plan"]["nodes"]] == [
            (5, "lenze-8400-motec-canopen", "Conveyor"), (7, "generic-cia402-servo", "Axis"),
            (12, "lenze-8200-vector-emf2178ib", "Fan")]
        axis = body["project"]["nodes"][1]
        stored = fresh.get(f"/api/parameter-sets/{axis['parameter_set']['set_id']}").json()
        assert stored["name"] == "Axis set"
        assert {v["ref"]: v["raw"] for v in stored["values"]} == {"0x1800.3": 250, "0x1801.5": 40, "0x605A": 5}
        again = json.loads(fresh.get(f"/api/line-projects/{body['id']}/export").text)
    first = json.loads(demo_api.get(f"/api/line-projects/{made['id']}/export").text)
    for document in (first, again):
        for node in document["nodes"]:
            if node["parameter_set"]:
                node["parameter_set"]["set_id"] = None
    assert again == first


def test_yaml_is_lely_dcfgen_shaped(demo_api: TestClient) -> None:
    made = make_project(demo_api)
    document = yaml.safe_load(demo_api.get(f"/api/line-projects/{made['id']}/export",
                                           params={"format": "yaml"}).text)
    assert document["master"]["node_id"] == 1 and document["master"]["baudrate"] == 500
    axis = document["axis_7"]
    assert (axis["node_id"], axis["dcf"], axis["product_code"], axis["revision_number"], axis["mandatory"]) == (
        7, "generic-cia402-servo.eds", 0x402001, 0x10000, True)
    assert document["fan_12"]["mandatory"] is False
    assert {(e["index"], e["sub_index"], e["value"]) for e in axis["sdo"]} == {
        (0x605A, 0, 5), (0x1800, 3, 250), (0x1801, 5, 40)}


BROKEN_JSON = '{\n  "schema_version": 1,\n  "name": "x",\n  "nodes": [\n    {"node_id": 5 "device": "a"}\n  ]\n}\n'
BAD_VALUE_JSON = ('{\n  "schema_version": 1,\n  "name": "x",\n  "nodes": [\n    {\n      "node_id": 200,\n'
                  '      "device": "generic-cia402-servo",\n      "baud_kbit": 500\n    }\n  ]\n}\n')
BROKEN_YAML = "master:\n  node_id: 1\naxis_7:\n  node_id: 7\n   dcf: x.eds\n"
BAD_VALUE_YAML = "master:\n  node_id: 1\n  baudrate: 500\naxis_7:\n  dcf: generic-cia402-servo.eds\n  node_id: 300\n"


@pytest.mark.parametrize(("filename", "content", "words"), [
    ("broken.json", BROKEN_JSON, "broken.json, line 5: Expecting ','"),
    ("bad.json", BAD_VALUE_JSON, "bad.json, line 6: nodes > 0 > node_id: Input should be less than or equal to 127"),
    ("broken.yaml", BROKEN_YAML, "broken.yaml, line 5: "),
    ("bad.yml", BAD_VALUE_YAML, "bad.yml, line 6: axis_7 > node_id: Input should be less than or equal to 127"),
])
def test_a_file_that_does_not_parse_names_file_line_reason_and_stores_nothing(
        demo_api: TestClient, filename: str, content: str, words: str) -> None:
    response = demo_api.post("/api/line-projects/import", params={"filename": filename}, content=content.encode())
    assert response.status_code == 422, response.text
    assert words in response.json()["detail"]
    assert demo_api.get("/api/line-projects").json() == []
    assert demo_api.get("/api/planned-networks").json() == []


def _changed(api: TestClient, made: dict[str, Any], change: Any) -> int:
    document = json.loads(api.get(f"/api/line-projects/{made['id']}/export").text)
    change(document)
    opened = api.post("/api/line-projects/import", params={"filename": "changed.json"},
                      content=json.dumps(document).encode())
    assert opened.status_code == 201, opened.text
    return int(opened.json()["id"])


def test_boot_up_check_passes_for_the_demo_plant_and_names_each_difference(demo_api: TestClient) -> None:
    made = make_project(demo_api)
    passed = demo_api.post(f"/api/line-projects/{made['id']}/boot-check", params={"session": SESSION})
    assert passed.status_code == 200, passed.text
    body = passed.json()
    assert body["ok"] is True
    assert [(n["node_id"], n["status"]) for n in body["nodes"]] == [(5, "ok"), (7, "ok"), (12, "ok")]
    assert body["nodes"][1]["read"]["product_code"] == "0x00402001"

    def change(document: dict[str, Any]) -> None:
        nodes = document["nodes"]
        nodes[0]["identity"]["product_code"] = "0x12345678"
        nodes[1]["identity"]["revision_min"] = "0x00020000"
        nodes[1]["identity"]["revision_max"] = "0x0002FFFF"
        nodes.append({"node_id": 20, "name": "Spare", "device": "generic-cia402-servo", "baud_kbit": 500,
                      "mandatory": True})
        nodes.append({"node_id": 21, "name": "Option", "device": "generic-cia402-servo", "baud_kbit": 500,
                      "mandatory": False})
    changed = _changed(demo_api, made, change)
    body = demo_api.post(f"/api/line-projects/{changed}/boot-check", params={"session": SESSION}).json()
    assert body["ok"] is False
    found = {n["node_id"]: (n["status"], n["messages"]) for n in body["nodes"]}
    conveyor_code = found[5][1][0]
    assert found[5][0] == "differs" and conveyor_code.startswith("node 5: product code 0x")
    assert conveyor_code.endswith("differs from the project's 0x12345678.")
    assert found[7] == ("differs", ["node 7: revision 0x00010000 is outside the project's range 0x00020000 to "
                                    "0x0002FFFF."])
    assert found[12][0] == "ok"
    assert found[20][0] == "missing" and found[20][1][0].startswith("node 20 missing (mandatory)")
    assert found[21][0] == "missing" and found[21][1][0].startswith("node 21 missing (optional)")


def test_concise_dcf_preview_file_and_download_entry_by_entry(demo_api: TestClient) -> None:
    made = make_project(demo_api)
    base = f"/api/line-projects/{made['id']}/nodes/7/concise-dcf"
    preview = demo_api.get(base).json()
    assert [(line["ref"], line["name"], line["value"]) for line in preview["lines"]] == [
        ("0x1800.3", "TPDO 1 communication parameter: Inhibit time", "250"),
        ("0x1801.5", "TPDO 2 communication parameter: Event timer", "40"),
        ("0x605A", "Quick stop option code", "5")]
    data = demo_api.get(base + ".bin").content
    assert read_concise_dcf(data) == [(0x1800, 3, (250).to_bytes(2, "little")), (0x1801, 5, (40).to_bytes(2, "little")),
                                      (0x605A, 0, (5).to_bytes(2, "little"))]
    sent = confirmed(demo_api, "POST", base + "/download", json={"session": SESSION})
    assert sent.status_code == 200, sent.text
    assert sent.json() == {"node_id": 7, "transfer": "entries", "written": 3, "failed": []}
    for ref, raw in (("0x1800.3", 250), ("0x1801.5", 40), ("0x605A", 5)):
        read = demo_api.get(f"/api/sessions/{SESSION}/nodes/7/parameters/{ref}").json()
        assert read["raw"] == raw, read
    logged = [(row["node_id"], row["ref"]) for row in demo_api.get("/api/audit").json()
              if row["origin"] == "concise-dcf"]
    assert sorted(logged) == [(7, "0x1800.3"), (7, "0x1801.5"), (7, "0x605A")]


def test_a_concise_dcf_with_a_moving_value_asks_first_and_sends_nothing_unconfirmed(demo_api: TestClient) -> None:
    """0x6060 (modes of operation) can make the servo move: the download answers 428 naming node 7 and the value,
    writes nothing, and goes through once confirmed with those values."""
    made = make_project(demo_api)

    def moving_mode(document: dict[str, Any]) -> None:
        document["nodes"][1]["parameter_set"]["values"] = {"0x605A": 6, "0x6060": 3}
    changed = _changed(demo_api, made, moving_mode)
    url = f"/api/line-projects/{changed}/nodes/7/concise-dcf/download"
    before = {ref: demo_api.get(f"/api/sessions/{SESSION}/nodes/7/parameters/{ref}").json()["raw"]
              for ref in ("0x605A", "0x6060", "0x1800.3")}
    asked = demo_api.post(url, json={"session": SESSION})
    assert asked.status_code == 428, asked.text
    problem = asked.json()
    assert problem["confirm_node"] == 7
    assert [key for key in problem["confirm_values"] if key.startswith("0x6060")], problem["confirm_values"]
    assert {ref: demo_api.get(f"/api/sessions/{SESSION}/nodes/7/parameters/{ref}").json()["raw"]
            for ref in before} == before  # nothing sent
    sent = confirmed(demo_api, "POST", url, json={"session": SESSION})
    assert sent.status_code == 200, sent.text
    assert sent.json()["written"] == 4 and sent.json()["failed"] == []
    assert demo_api.get(f"/api/sessions/{SESSION}/nodes/7/parameters/0x6060").json()["raw"] == 3


def test_the_masters_dcf_holds_slave_assignment_and_expected_identity(demo_api: TestClient) -> None:
    """CiA 302-2: 0x1F81 (bit 0 slave, bit 2 boot slave, bit 3 mandatory) and 0x1F84-0x1F88, sub-index = node."""
    made = make_project(demo_api)
    entries = read_concise_dcf(demo_api.get(f"/api/line-projects/{made['id']}/master-dcf.bin").content)
    found = {(index, sub): int.from_bytes(data, "little") for index, sub, data in entries}
    assert all(len(data) == 4 for _index, _sub, data in entries)
    assert (found[(0x1F81, 7)], found[(0x1F81, 12)]) == (0x0D, 0x05)  # 12 is optional
    assert (found[(0x1F86, 7)], found[(0x1F87, 7)], found[(0x1F88, 7)]) == (0x402001, 0x10000, 0)
    shown = demo_api.get(f"/api/line-projects/{made['id']}/master-dcf").json()
    assert shown["count"] == len(entries) == 6 * 3
    assert {line["name"] for line in shown["lines"]} >= {"NMT slave assignment", "Product code"}


def test_a_set_value_that_does_not_fit_its_profile_refuses_the_project_and_stores_nothing(
        demo_api: TestClient) -> None:
    made = make_project(demo_api)
    document = json.loads(demo_api.get(f"/api/line-projects/{made['id']}/export").text)
    document["nodes"][1]["parameter_set"]["values"] = {"0x605A": 99999, "0x9999": 1}
    networks = len(demo_api.get("/api/planned-networks").json())
    refused = demo_api.post("/api/line-projects/import", params={"filename": "unfit.json"},
                            content=json.dumps(document).encode())
    assert refused.status_code == 422, refused.text
    assert "node 7 of the project" in refused.text and "0x605A" in refused.text and "0x9999" in refused.text
    assert len(demo_api.get("/api/planned-networks").json()) == networks
    assert len(demo_api.get("/api/line-projects").json()) == 1


def test_a_nodes_dcf_becomes_a_concise_dcf(demo_api: TestClient) -> None:
    """The set's DCF (as the Parameter sets page exports it) in, its ParameterValues as 0x1F22 bytes out."""
    made = make_project(demo_api)
    set_id = made["project"]["nodes"][1]["parameter_set"]["set_id"]
    dcf = demo_api.get(f"/api/parameter-sets/{set_id}/export", params={"format": "dcf"})
    assert dcf.status_code == 200, dcf.text
    shown = demo_api.post("/api/line-projects/concise-dcf/from-dcf", params={"filename": "axis.dcf"},
                          content=dcf.content)
    assert shown.status_code == 200, shown.text
    entries = read_concise_dcf(base64.b64decode(shown.json()["base64"]))
    assert sorted(entries) == [(0x1800, 3, (250).to_bytes(2, "little")), (0x1801, 5, (40).to_bytes(2, "little")),
                               (0x605A, 0, (5).to_bytes(2, "little"))]
    broken = demo_api.post("/api/line-projects/concise-dcf/from-dcf", params={"filename": "x.dcf"},
                           content=b"[1000]\nnot an ini line\n")
    assert broken.status_code == 422 and "x.dcf" in broken.text
