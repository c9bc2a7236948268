"""Writes that can make a drive move, by every route, over the real HTTP API against the simulated demo plant
(issue 16, items 1 and 4): an engineer's parameter write of a command source, control word, setpoint or mode needs
the confirmation naming the node (428 in words without it), a confirmed one arms the keep-alive guard, and when the
keep-alive stops the drive is quick-stopped; a control word that only stops passes unasked. The same for the 8400
motec (node 5), the 8200 vector (node 12), a drive known only by its EDS (CiA 402 indices) and a parameter-set
download. Only the user that armed a drive keeps it alive: a viewer's keep-alives do not."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.node import SimulatedNode
from tests.confirming import confirmed
from tests.conftest import wait_until
from tests.web.test_access import app_client, own_db, users  # noqa: F401  (fixtures)

DEMO = "demo-plant"
MM, MOTEC, VECTOR = 3, 5, 12
NEW_DRIVE_EDS = Path(__file__).parents[1] / "data" / "eds" / "new_drive_cia402.eds"


def _param(node: int, ref: str) -> str:
    return f"/api/sessions/{DEMO}/nodes/{node}/parameters/{ref}"


def _sim(client: TestClient, node: int) -> SimulatedNode:
    sim: SimulatedNode = client.app.state.drivebench.plants[DEMO].nodes[node]  # type: ignore[attr-defined]
    return sim


def _bearer(token: str, tab: str | None = None) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", **({"X-DriveBench-Client": tab} if tab else {})}


def _refused(client: TestClient, headers: dict[str, str], node: int, ref: str, value: Any) -> str:
    answer = client.put(_param(node, ref), json={"value": value}, headers=headers)
    assert answer.status_code == 428, f"{ref} = {value}: {answer.status_code} {answer.text}"
    assert answer.headers["content-type"] == "application/problem+json"
    detail = str(answer.json()["detail"])
    assert f"lets node {node} move a drive: confirm it with confirm = '{node}'" in detail, detail
    return detail


def _written(client: TestClient, headers: dict[str, str], node: int, ref: str, value: Any,
             confirm: int | None = None) -> None:
    answer = confirmed(client, "PUT", _param(node, ref), json={"value": value, "confirm": confirm, "verify": False},
                       headers=headers)
    assert answer.status_code == 200, f"{ref} = {value}: {answer.text}"


def _keepalive(client: TestClient, headers: dict[str, str]) -> dict[str, Any]:
    answer = client.post(f"/api/sessions/{DEMO}/keepalive", headers=headers)
    assert answer.status_code == 200, answer.text
    kept: dict[str, Any] = answer.json()
    return kept


def _last_trip(client: TestClient, headers: dict[str, str], node: int) -> str:
    return str(client.get(f"/api/sessions/{DEMO}/nodes/{node}/control", headers=headers).json()["last_trip"] or "")


# --- the reported attack on the MICROMASTER ---------------------------------------------------------------------
def test_the_reported_parameter_api_run_of_the_micromaster(users: dict[str, str],  # noqa: F811
                                                            app_client: TestClient) -> None:  # noqa: F811
    eve = _bearer(users["eve"])  # an engineer
    sim = _sim(app_client, MM)
    sim.store.set_ref("P1120", 0.5)  # test-only: a 0.5 s ramp-up
    for ref in ("P0700", "P1000"):  # command / setpoint source: switching it hands the motor to the new source
        assert "Writing " + ref in _refused(app_client, eve, MM, ref, 6)
    assert sim.store.get_ref("P0700") != 6, "nothing was written without the confirmation"
    _written(app_client, eve, MM, "P0700", 6, confirm=MM)
    assert _keepalive(app_client, eve)["nodes"] == [MM], "the confirmed write armed the guard for eve"
    _written(app_client, eve, MM, "P1000", 6, confirm=MM)
    _written(app_client, eve, MM, "0x6040", 0x06)  # shutdown and switch on cannot move it: no question
    _written(app_client, eve, MM, "0x6040", 0x07)
    _refused(app_client, eve, MM, "0x6040", 0x7F)
    _refused(app_client, eve, MM, "0x6042", 600)
    assert sim.drive.speed_rpm == 0  # type: ignore[union-attr]
    _written(app_client, eve, MM, "0x6040", 0x7F, confirm=MM)
    _written(app_client, eve, MM, "0x6042", 600, confirm=MM)

    def running_kept_alive() -> bool:
        assert _keepalive(app_client, eve)["nodes"] == [MM]
        return sim.drive.speed_rpm >= 590  # type: ignore[union-attr]

    assert wait_until(running_kept_alive), "the confirmed, kept-alive drive runs up to 600 rpm"
    # eve goes silent: within the 2 s deadline the guard quick-stops the drive
    assert wait_until(lambda: sim.store.get(0x6040, 0) & 0x06 == 0x02, 6), "no quick stop in 0x6040"
    assert wait_until(lambda: sim.drive.speed_rpm == 0, 6)  # type: ignore[union-attr]
    assert "no keep-alive for 2 s" in _last_trip(app_client, eve, MM)
    assert _keepalive(app_client, eve)["nodes"] == []


def test_stopping_control_words_are_never_refused(users: dict[str, str],  # noqa: F811
                                                  app_client: TestClient) -> None:  # noqa: F811
    """Another engineer's lease on the node refuses his writes, but not a quick stop or disable."""
    root, eve = _bearer(users["root"]), _bearer(users["eve"])
    _written(app_client, root, MM, "P1120", 5)  # root now holds node 3's write lease
    assert app_client.put(_param(MM, "P1120"), json={"value": 6}, headers=eve).status_code == 409
    _written(app_client, eve, MM, "0x6040", 0x02)  # quick stop
    _written(app_client, eve, MM, "0x6040", 0x00)  # disable voltage


# --- the Lenze drives: 8400 motec and 8200 vector ---------------------------------------------------------------
@pytest.mark.parametrize(("node", "word", "enable", "inhibit", "setpoint"), [
    (MOTEC, "C00866/1", 0x0009, 0x0100, "C00866/2"),  # CAN1_IN word 1: SwitchOn + EnableOperation; SetCInh
    (VECTOR, "C0135", 0x0000, 0x0200, "C1822/2"),  # AIF-CTRL: CINH and QSP cleared; CINH set
])
def test_lenze_control_words_and_setpoints(users: dict[str, str], app_client: TestClient,  # noqa: F811
                                           node: int, word: str, enable: int, inhibit: int, setpoint: str) -> None:
    eve = _bearer(users["eve"])
    sim = _sim(app_client, node)
    if node == VECTOR:
        _refused(app_client, eve, node, "C0001", 3)  # setpoint source "process data": the AIF takes the motor
        _written(app_client, eve, node, "C0001", 3, confirm=node)
    _written(app_client, eve, node, word, inhibit)  # controller inhibit: no question
    _refused(app_client, eve, node, word, enable)
    _refused(app_client, eve, node, setpoint, 1250)
    _written(app_client, eve, node, setpoint, 0)
    _written(app_client, eve, node, setpoint, 1250, confirm=node)
    _written(app_client, eve, node, word, enable, confirm=node)
    assert wait_until(lambda: _keepalive(app_client, eve)["nodes"] == [node] and sim.drive.running)  # type: ignore[union-attr]
    assert wait_until(lambda: sim.drive.quick_stop(), 6), f"{word}: no quick stop after the keep-alive stopped"  # type: ignore[union-attr]
    assert "no keep-alive" in _last_trip(app_client, eve, node)


# --- a drive known only by its EDS ------------------------------------------------------------------------------
def test_an_uploaded_eds_of_a_new_cia402_drive_is_covered(users: dict[str, str],  # noqa: F811
                                                          app_client: TestClient) -> None:  # noqa: F811
    root, eve = _bearer(users["root"]), _bearer(users["eve"])
    uploaded = app_client.post("/api/profiles", headers=root,
                               files={"file": ("new_drive_cia402.eds", NEW_DRIVE_EDS.read_bytes())})
    assert uploaded.status_code == 201, uploaded.text
    profile_id = uploaded.json()["id"]
    schema = app_client.get("/api/profiles/schema", headers=root).json()
    assert "motion" in json.dumps(schema), "the profile field is part of the published schema"
    assert app_client.delete(f"/api/sessions/{DEMO}/nodes/{MM}", headers=root).status_code == 204
    added = app_client.post(f"/api/sessions/{DEMO}/nodes", json={"node_id": MM, "profile_id": profile_id},
                            headers=root)
    assert added.status_code == 201, added.text
    for ref, value in (("0x6040", 0x0F), ("0x60FF", 100), ("0x6071", 50), ("0x607A", 0), ("0x6060", 3),
                       ("0x1F80", 0x04)):
        _refused(app_client, eve, MM, ref, value)
    acceleration = app_client.put(_param(MM, "0x6083"), json={"value": 500}, headers=eve)  # moves nothing itself
    assert acceleration.status_code == 404 and "SDO abort" in acceleration.json()["detail"], "sent unasked"
    _written(app_client, eve, MM, "0x6040", 0x06)
    sim = _sim(app_client, MM)
    sim.store.set_ref("P0700", 6)  # the simulated drive behind it is a MICROMASTER: control from CAN
    _written(app_client, eve, MM, "0x6040", 0x0F, confirm=MM)
    assert _keepalive(app_client, eve)["nodes"] == [MM]
    assert wait_until(lambda: sim.store.get(0x6040, 0) & 0x06 == 0x02, 6), "no quick stop after the silence"


# --- a parameter-set download ----------------------------------------------------------------------------------
def _finish(client: TestClient, job: dict[str, Any]) -> dict[str, Any]:
    end = time.monotonic() + 30
    while job["state"] == "running":
        assert time.monotonic() < end, f"job {job['id']} still running"
        time.sleep(0.05)
        job = client.get(f"/api/parameter-sets/jobs/{job['id']}").json()
    return job


def test_a_set_download_with_a_control_word_needs_the_confirmation(demo_api: TestClient) -> None:
    api, sets = demo_api, "/api/parameter-sets"
    job = _finish(api, api.post(f"{sets}/upload", json={"session_id": DEMO, "node_id": MOTEC, "name": "Conveyor"})
                  .json())
    exported = json.loads(api.get(f"{sets}/{job['set_id']}/export").text)
    # An upload leaves the process data out (issue 28 item 1); a set file may still carry the control word.
    exported["parameters"] = [p for p in exported["parameters"] if p["ref"] != "C00866/1"]
    exported["parameters"].append({"ref": "C00866/1", "value": 0x0009})  # SwitchOn + EnableOperation
    exported["name"] = "Conveyor running"
    running = api.post(f"{sets}/import", files={"file": ("c.json", json.dumps(exported).encode())}).json()["set"]
    sim = _sim(api, MOTEC)
    target = {"session_id": DEMO, "node_id": MOTEC}
    refused = api.post(f"{sets}/{running['id']}/download", json=target)
    assert refused.status_code == 428 and "C00866/1" in refused.json()["detail"], refused.text
    page = api.post(f"/parameter-sets/{running['id']}/download", data={"target": f"{DEMO}:{MOTEC}"})
    assert page.status_code == 428 and "confirm = &#39;5&#39;" in page.text, page.text  # the sets page asks (app.js)
    assert f'data-keepalive="/ws/sessions/{DEMO}/keepalive"' in api.get("/parameter-sets").text
    assert sim.store.get_ref("C00866/1") == 0 and not sim.drive.running  # type: ignore[union-attr]
    done = _finish(api, confirmed(api, "POST", f"{sets}/{running['id']}/download",
                                  json={**target, "confirm": MOTEC}).json())
    assert done["download_state"] == "done", done
    assert _keepalive(api, {})["nodes"] == [MOTEC], "the download's control word armed the guard"
    assert wait_until(lambda: sim.drive.quick_stop(), 6), "no quick stop after the keep-alive stopped"  # type: ignore[union-attr]


# --- item 4: only the user that armed a drive keeps it alive ----------------------------------------------------
def test_a_viewer_does_not_keep_an_engineers_drive_running(users: dict[str, str],  # noqa: F811
                                                           app_client: TestClient) -> None:  # noqa: F811
    eve, vera = _bearer(users["eve"], "tab-1"), _bearer(users["vera"], "tab-1")  # even with the same client id
    sim = _sim(app_client, MOTEC)
    started = confirmed(app_client, "POST", f"/api/sessions/{DEMO}/nodes/{MOTEC}/nmt",
                        json={"command": "start", "confirm": MOTEC},
                        headers=eve)
    assert started.status_code == 200, started.text
    assert wait_until(lambda: sim.state.name == "OPERATIONAL")
    armed_at = time.monotonic()
    with app_client.websocket_connect(f"/ws/sessions/{DEMO}/keepalive?client=tab-1", headers=vera) as socket:
        socket.send_text('{"cmd": "keepalive"}')  # the viewer's page socket, same tab id: holds nothing
        held = socket.receive_json()
        assert held["nodes"] == [] and [n["node"] for n in held["not_held"]] == [MOTEC], held
    kept = _keepalive(app_client, vera)
    assert kept["nodes"] == [] and [held["node"] for held in kept["not_held"]] == [MOTEC], kept
    assert "eve" in kept["not_held"][0]["holder"], "the answer says who holds the node it does not keep alive"
    while sim.state.name == "OPERATIONAL":
        assert time.monotonic() - armed_at < 6, "the viewer's keep-alives held the node past its 2 s deadline"
        assert _keepalive(app_client, vera)["nodes"] == []
        node_keepalive = app_client.post(f"/api/sessions/{DEMO}/nodes/{MOTEC}/control/keepalive", headers=vera)
        assert node_keepalive.status_code in (200, 403) and not node_keepalive.json().get("armed")
        time.sleep(0.5)
    assert time.monotonic() - armed_at >= 1.5, "stopped at the deadline, not before"
    assert "no keep-alive for 2 s" in _last_trip(app_client, eve, MOTEC)
