"""The "New line" wizard through the real HTTP API on plants/new-line.json (four devices without node ID on the real
python-can virtual bus): a whole run from a line project file (scan, assign, store, boot-up check, parameter sets,
program download, report), the confirmation naming every device, the refusal while a drive is enabled, and a run
resumed after the app restarted on the same database."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.line.wizard_run import WizardStore
from drivebench.services.users import audit
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import fresh_channel
from tests.line_wizard_project import AXIS_FIRMWARE, AXIS_VERSION, new_line_project

NEW_LINE = REPO_ROOT / "plants" / "new-line.json"
WIZARD = "/api/sessions/new-line/line-wizard"


def new_line_app(channel: str) -> Any:
    return create_app(plant_file=NEW_LINE, plant_bus=f"virtual:{channel}@500000", latency="0ms")


@pytest.fixture
def line_api(app_db_url: str) -> Iterator[TestClient]:
    with TestClient(new_line_app(fresh_channel())) as client:
        yield client


def open_project(api: TestClient, registry: ProfileRegistry) -> int:
    opened = api.post("/api/line-projects/import?filename=new-line.json",
                      content=json.dumps(new_line_project(registry)).encode())
    assert opened.status_code == 201, opened.text
    return int(opened.json()["id"])


def step(api: TestClient, run_id: int, name: str) -> dict[str, Any]:
    answer = confirmed(api, "POST", f"{WIZARD}/{run_id}/steps/{name}", json={})
    assert answer.status_code == 200, answer.text
    return dict(answer.json())


def test_a_whole_run_commissions_the_new_line_and_reports_every_step(line_api: TestClient,
                                                                    registry: ProfileRegistry) -> None:
    project_id = open_project(line_api, registry)
    made = line_api.post(WIZARD, json={"project_id": project_id})
    assert made.status_code == 201, made.text
    run_id = made.json()["id"]

    asked = line_api.post(f"{WIZARD}/{run_id}/steps/scan", json={})
    assert asked.status_code == 428
    assert asked.json()["confirm_node"] == "all"
    assert asked.json()["confirm_values"]["reaches"] == "all nodes on this bus"
    assert line_api.get(f"{WIZARD}/{run_id}").json()["steps"]["scan"]["state"] == "pending"

    run = step(line_api, run_id, "scan")
    assert run["steps"]["scan"]["state"] == "done"
    assert run["steps"]["scan"]["lines"][0].startswith("4 devices without node ID found")
    scan_lines = "\n".join(run["steps"]["scan"]["lines"])  # told by their answers, as the LSS page tells them
    assert "unknown device" not in scan_lines and scan_lines.count("Lenze (vendor ID 0x0000003B)") == 2
    assert sorted(device["device"] for device in run["found"]).count("Lenze") == 2
    # the project names the Lenze devices' serials; pump and axis are told apart by vendor and product
    assert run["proposed"] == {"20": "0x000003E9", "21": "0x000007D2", "22": "0x00000BBB", "23": "0x00000FA4"}
    twice = line_api.put(f"{WIZARD}/{run_id}/assignments", json={"20": "0x000003E9", "21": "0x000003E9"})
    assert twice.status_code == 422
    assert "given to two nodes" in twice.json()["detail"]
    chosen = line_api.put(f"{WIZARD}/{run_id}/assignments", json=run["proposed"])
    assert chosen.status_code == 200, chosen.text

    asked = line_api.post(f"{WIZARD}/{run_id}/steps/assign", json={})
    assert asked.status_code == 428
    assert asked.json()["confirm_values"]["nodes"][0] == "serial 0x000003E9 -> node 20, 500000 bit/s"
    run = step(line_api, run_id, "assign")
    assert run["steps"]["assign"]["state"] == "done", run["steps"]["assign"]["lines"]
    assert any("node 20 booted (boot-up telegram)" in line for line in run["steps"]["assign"]["lines"])
    nodes = {node["node_id"]: node for node in line_api.get("/api/sessions/new-line/nodes").json()}
    assert sorted(nodes) == [20, 21, 22, 23]

    run = step(line_api, run_id, "store")
    assert run["steps"]["store"]["state"] == "done", run["steps"]["store"]["lines"]
    assert all("configuration stored in the device" in line for line in run["steps"]["store"]["lines"])
    run = step(line_api, run_id, "boot_check")
    assert run["steps"]["boot_check"]["lines"][-1] == "The line matches its project."
    run = step(line_api, run_id, "sets")
    assert run["steps"]["sets"]["state"] == "done", run["steps"]["sets"]["lines"]
    axis = line_api.get("/api/sessions/new-line/nodes/23/parameters/0x6083").json()
    assert axis["raw"] == 5000

    run = step(line_api, run_id, "program")
    assert run["steps"]["program"]["state"] == "failed"
    assert f"the project expects {AXIS_VERSION}: choose the firmware file" in run["steps"]["program"]["lines"][0]
    chosen_file = line_api.post(f"{WIZARD}/{run_id}/firmware/23", files={"file": ("axis.bin", AXIS_FIRMWARE)})
    assert chosen_file.status_code == 200, chosen_file.text
    asked = line_api.post(f"{WIZARD}/{run_id}/steps/program", json={})
    assert asked.status_code == 428
    assert "node 23: 0x1F50 Program data" in asked.json()["confirm_values"]
    run = step(line_api, run_id, "program")
    assert run["steps"]["program"]["state"] == "done", run["steps"]["program"]["lines"]
    assert AXIS_VERSION in run["steps"]["program"]["lines"][0]

    report = line_api.get(f"{WIZARD}/{run_id}/report?download=1")
    assert report.status_code == 200
    assert report.headers["content-disposition"] == f'attachment; filename="new-line-report-{run_id}.json"'
    body = report.json()
    assert body["complete"] is True
    assert body["verdict"] == "The line is commissioned: every step is done."
    assert [entry["step"] for entry in body["steps"]] == ["scan", "assign", "store", "boot_check", "sets", "program"]
    assert {str(node["node_id"]): node["serial"] for node in body["nodes"]} == run["proposed"]
    rows = audit.entries(session_id="new-line")
    assert any(row.new_value.startswith("store configuration: 0x000003E9") for row in rows)


def test_a_step_is_refused_while_a_drive_is_enabled_and_keeps_its_state(line_api: TestClient,
                                                                        registry: ProfileRegistry) -> None:
    run_id = line_api.post(WIZARD, json={"project_id": open_project(line_api, registry)}).json()["id"]
    step(line_api, run_id, "scan")
    step(line_api, run_id, "assign")
    started = confirmed(line_api, "POST", "/api/sessions/new-line/nodes/23/nmt",
                        json={"command": "start", "keepalive_s": 10})
    assert started.status_code == 200, started.text
    refused = confirmed(line_api, "POST", f"{WIZARD}/{run_id}/steps/store", json={})
    assert refused.status_code == 409
    assert "refused while node 23 is enabled or armed" in refused.json()["detail"]
    assert line_api.get(f"{WIZARD}/{run_id}").json()["steps"]["store"]["state"] == "pending"


def test_a_run_resumes_after_the_server_restarted_on_the_same_database(app_db_url: str,
                                                                       registry: ProfileRegistry) -> None:
    channel = fresh_channel()
    with TestClient(new_line_app(channel)) as first:
        run_id = first.post(WIZARD, json={"project_id": open_project(first, registry)}).json()["id"]
        step(first, run_id, "scan")
        first.put(f"{WIZARD}/{run_id}/assignments", json={"20": "0x000003E9", "23": "0x00000FA4"})
    stored = WizardStore().get(run_id)
    stored.steps["assign"].state, stored.steps["assign"].runs = "running", 1  # as a server stopped mid-step left it
    WizardStore().save(stored)

    with TestClient(new_line_app(channel)) as second:
        run = second.get(f"{WIZARD}/{run_id}").json()
        assert run["steps"]["scan"]["state"] == "done"
        assert run["assignments"] == {"20": "0x000003E9", "23": "0x00000FA4"}
        assert run["steps"]["assign"]["state"] == "interrupted"
        assert "The server stopped while this step ran: run it again." in run["steps"]["assign"]["lines"]
        assert [listed["id"] for listed in second.get(WIZARD).json()] == [run_id]
        run = step(second, run_id, "assign")  # the devices found before the restart, by their stored addresses
        assert run["steps"]["assign"]["state"] == "done", run["steps"]["assign"]["lines"]
        assert run["steps"]["assign"]["runs"] == 2
        nodes = [node["node_id"] for node in second.get("/api/sessions/new-line/nodes").json()]
        assert nodes == [20, 23]


def test_confirmed_values_that_no_longer_hold_are_asked_again(line_api: TestClient, registry: ProfileRegistry) -> None:
    run_id = line_api.post(WIZARD, json={"project_id": open_project(line_api, registry)}).json()["id"]
    step(line_api, run_id, "scan")
    line_api.put(f"{WIZARD}/{run_id}/assignments", json={"22": "0x00000BBB"})
    asked = line_api.post(f"{WIZARD}/{run_id}/steps/assign", json={}).json()
    line_api.put(f"{WIZARD}/{run_id}/assignments", json={"22": "0x00000FA4"})  # changed after the question
    again = line_api.post(f"{WIZARD}/{run_id}/steps/assign",
                          json={"confirm": asked["confirm_node"], "confirm_values": asked["confirm_values"]})
    assert again.status_code == 428
    assert "changed since they were confirmed" in again.json()["detail"]
    assert again.json()["confirm_values"]["nodes"] == ["serial 0x00000FA4 -> node 22, 500000 bit/s"]
    assert [node["node_id"] for node in line_api.get("/api/sessions/new-line/nodes").json()] == []


def test_a_set_value_that_can_move_a_drive_is_asked_for_naming_its_node(app_db_url: str,
                                                                         registry: ProfileRegistry) -> None:
    document = new_line_project(registry)
    document["nodes"][3]["parameter_set"]["values"]["0x6060"] = 3  # modes of operation: profile velocity
    with TestClient(new_line_app(fresh_channel())) as api:
        opened = api.post("/api/line-projects/import?filename=moving.json", content=json.dumps(document).encode())
        assert opened.status_code == 201, opened.text
        run_id = api.post(WIZARD, json={"project_id": opened.json()["id"]}).json()["id"]
        for name in ("scan", "assign"):
            step(api, run_id, name)
        asked = api.post(f"{WIZARD}/{run_id}/steps/sets", json={})
        assert asked.status_code == 428, asked.text
        assert asked.json()["confirm_node"] == "all"
        assert [key for key in asked.json()["confirm_values"] if key.startswith("node 23: 0x6060")]
        assert api.get(f"{WIZARD}/{run_id}").json()["steps"]["sets"]["state"] == "pending"
        assert api.get("/api/sessions/new-line/nodes/23/parameters/0x6083").json()["raw"] != 5000  # nothing sent
        run = step(api, run_id, "sets")
        assert run["steps"]["sets"]["state"] == "done", run["steps"]["sets"]["lines"]
        assert api.get("/api/sessions/new-line/nodes/23/parameters/0x6060").json()["raw"] == 3
