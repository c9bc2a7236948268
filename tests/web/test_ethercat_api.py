"""The demo plant's second session, "EtherCAT line" (two simulated 8400 motec EtherCAT units behind a simulated
master's mailbox gateway on UDP 127.0.0.1), through the REST API: the slave list, a parameter-set round trip
(upload, compare, download with save, rollback) and the Plant page's slave table."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import ObjectEntry
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from tests.confirming import confirmed
from tests.conftest import wait_for_value
from tests.web.test_parameter_sets_api import SETS, finish
from tests.web.test_pdo_api import give_changed_profile

SESSION = "ethercat-line"
NODE = f"/api/sessions/{SESSION}/nodes/1"


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_the_demo_plant_has_an_ethercat_line(demo_api: TestClient) -> None:
    sessions = {s["id"]: s for s in demo_api.get("/api/sessions").json()}
    assert sessions[SESSION]["interface"] == "ethercat-mbg" and sessions[SESSION]["simulated"] is True
    nodes = demo_api.get(f"/api/sessions/{SESSION}/nodes").json()
    assert [(n["node_id"], n["station"], n["profile_id"]) for n in nodes] == [
        (1, 1001, "lenze-8400-motec-ethercat"), (2, 1002, "lenze-8400-motec-ethercat")]
    page = demo_api.get("/").text
    assert 'id="node-ethercat-line-1"' in page and ">1001<" in page and "EtherCAT state (AL status)" in page
    diagnostics = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/diagnostics").text
    assert 'id="diag-ethercat"' in diagnostics and "<dd>1001</dd>" in diagnostics
    assert "0x1017" not in diagnostics and "SDO transfer aborted" not in diagnostics  # no heartbeat asked for


def test_parameter_set_round_trip_on_the_ethercat_unit(demo_api: TestClient) -> None:
    started = demo_api.post(f"{SETS}/upload", json={"session_id": SESSION, "node_id": 1, "name": "Palletiser"},
                            headers={"X-DriveBench-User": "anna"})
    assert started.status_code == 202, started.text
    job = finish(demo_api, started.json())
    assert job["state"] == "done", job
    set_id = job["set_id"]
    values = {v["ref"]: v for v in demo_api.get(f"{SETS}/{set_id}").json()["values"]}
    assert values["C00039/1"]["raw"] == 0x0FA0

    exported = json.loads(demo_api.get(f"{SETS}/{set_id}/export").text)
    for parameter in exported["parameters"]:
        if parameter["ref"] == "C00039/1":
            parameter["value"] = 55.0
    exported["name"] = "Palletiser commissioned"
    new_id = demo_api.post(f"{SETS}/import",
                           files={"file": ("p.json", json.dumps(exported).encode())}).json()["set"]["id"]
    target = {"session_id": SESSION, "node_id": 1}
    compared = demo_api.post(f"{SETS}/compare", json={"left": {"kind": "node", **target},
                                                      "right": {"kind": "set", "set_id": new_id}}).json()
    assert [(row["ref"], row["left"], row["right"], row["kind"]) for row in compared["rows"]] == [
        ("C00039/1", "40.00 %", "55.00 %", "changed")]

    # the set holds C00007 (a command source) and setpoints, but the unit holds them already: the download writes
    # only C00039/1, which cannot move the drive, so it asks nothing (issue 28 item 2: exactly what will change)
    done = finish(demo_api, demo_api.post(f"{SETS}/{new_id}/download", json=dict(target, save=True),
                                          headers={"X-DriveBench-User": "bert"}).json())
    assert done["download_state"] == "done", done
    assert {line["ref"]: line["status"] for line in done["report"]}["C00039/1"] == "written"
    assert demo_api.get(f"{NODE}/parameters/C00039/1").json()["display"] == "55.00 %"

    back = finish(demo_api, demo_api.post(f"/api/parameter-downloads/{done['download_id']}/rollback",
                                          headers={"X-DriveBench-User": "bert"}).json())
    assert back["download_state"] == "done", back
    assert demo_api.get(f"{NODE}/parameters/C00039/1").json()["display"] == "40.00 %"


def test_the_monitor_counts_mailbox_traffic_per_slave(demo_api: TestClient) -> None:
    assert demo_api.get(f"{NODE}/parameters/C00039/1").status_code == 200
    refused = demo_api.put(f"{NODE}/parameters/0x1C12.1", json={"raw": 0x1600, "check": False})  # the device: abort
    assert refused.status_code >= 400
    page = demo_api.get(f"/monitor/{SESSION}").text
    assert "Mailbox traffic per slave" in page and 'id="mailbox-1"' in page
    block = demo_api.get(f"/ui/monitor/{SESSION}/mailbox").text
    row = block[block.index('id="mailbox-1"'):]
    cells = [cell.split("<")[0] for cell in row.split('<td class="num">')[1:]]
    node, station, requests, responses, aborts = (int(cells[i]) for i in (0, 1, 2, 3, 4))
    assert (node, station) == (1, 1001) and requests >= 2 and responses >= 2 and aborts >= 1

    unit = demo_api.app.state.drivebench.gateways[SESSION].slaves[1001]  # type: ignore[attr-defined]
    unit.raise_fault(0x1000, 0x01, bytes.fromhex("00 31 81 BC 01"))  # the manual's "Operational status quit"

    def emergencies() -> int:
        block = demo_api.get(f"/ui/monitor/{SESSION}/mailbox").text
        cells = block[block.index('id="mailbox-1"'):].split('<td class="num">')[1:]
        return int(cells[5].split("<")[0])
    assert wait_for_value(lambda: emergencies() == 1, 8, "the emergency counted for slave 1")
    assert "Mailbox traffic" not in demo_api.get("/monitor/demo-plant").text  # CAN: telegrams, no mailboxes


def test_the_session_form_opens_a_gateway_and_refuses_a_direct_master_in_words(demo_api: TestClient) -> None:
    htmx = {"HX-Request": "true"}
    gateway = demo_api.get(f"/api/sessions/{SESSION}").json()["channel"]
    again = demo_api.post("/ui/sessions", data={"interface": "ethercat-mbg", "channel": gateway, "name": "Again"},
                          headers=htmx)
    assert again.status_code == 409 and "already open as session" in again.text
    direct = demo_api.post("/ui/sessions", data={"interface": "ethercat", "channel": "eth9", "name": "Direct"},
                           headers=htmx)
    assert direct.status_code >= 400
    assert ("pip install &#39;drivebench[ethercat]&#39;" in direct.text or "CAP_NET_RAW" in direct.text
            or "no network card" in direct.text)
    assert 'value="ethercat-mbg"' in demo_api.get("/").text  # offered next to python-can's interfaces


def test_the_pdo_tab_shows_the_ethercat_rules_of_the_profile(demo_api: TestClient) -> None:
    pdo_list = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/pdo").text
    assert "0x1C12" in pdo_list and "0x1C13" in pdo_list and "0x1600" in pdo_list and "0x1A00" in pdo_list
    assert "Pre-Operational" in pdo_list and "0x08000022" in pdo_list
    assert "CAN1_IN" not in pdo_list and "COB-ID of TPDO2" not in pdo_list  # the CANopen unit's notes
    tab = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/tabs/pdo").text
    assert "Start SYNC" not in tab and "NMT operational" not in tab  # no SYNC or NMT on EtherCAT
    assert "Start SYNC" in demo_api.get("/ui/sessions/demo-plant/nodes/5/tabs/pdo").text


def test_the_parameters_tab_names_the_coe_mailbox_not_sdo2(demo_api: TestClient) -> None:
    gateway = demo_api.get(f"/api/sessions/{SESSION}").json()["channel"]
    tab = demo_api.get(f"/ui/sessions/{SESSION}/nodes/2/tabs/parameters").text
    summary = tab[tab.index('<details id="sdo-settings"'):]
    summary = summary[summary.index("<summary>") + 9:summary.index("</summary>")]
    assert summary.startswith(f"CoE mailbox (station 1002, gateway ethercat-mbg:{gateway}): ")
    assert "SDO2" not in summary and 'name="use_sdo2" value="1" ' not in tab
    can_tab = demo_api.get("/ui/sessions/demo-plant/nodes/5/tabs/parameters").text
    assert "<summary>SDO: " in can_tab and "SDO2</label>" in can_tab


@pytest.fixture
def changed_unit(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    """An 8400 motec EtherCAT unit whose object dictionary differs from the shipped profile: it has a vendor
    object 0x2100 the profile does not list and lacks 0x1C33 (Sync Man 3 Synchronization)."""
    shipped = registry.get("lenze-8400-motec-ethercat")
    extra = ObjectEntry.model_validate({"index": "0x2100", "subindex": 0, "name": "Vendor diagnosis word",
                                        "data_type": "UNSIGNED16", "access": "ro"})
    device = shipped.model_copy(update={"objects": [o for o in shipped.objects if o.index != 0x1C33] + [extra]})
    server = GatewayServer([SimulatedSlave(device, 1001, 0, name="Changed unit")]).start()
    yield server
    server.stop()


def test_the_info_tab_reads_the_object_list_and_compares_it_with_the_profile(
        demo_api: TestClient, changed_unit: GatewayServer) -> None:
    same = demo_api.post(f"/ui/sessions/{SESSION}/nodes/1/info/object-list")
    assert same.status_code == 200, same.text
    assert "The device reports 36 objects, the profile lists 36; 36 in both." in same.text
    info_tab = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/tabs/info").text
    assert same.text.count("none") == 2 and "Read object list from device" in info_tab
    assert "kbit/s" not in info_tab and "<dt>Heartbeat</dt>" not in info_tab  # no CAN bit rates on EtherCAT

    opened = demo_api.post("/api/sessions", json={"bus": changed_unit.spec, "name": "Changed"})
    assert opened.status_code == 201, opened.text
    session_id = opened.json()["id"]
    assert [n["profile_id"] for n in demo_api.post(f"/api/sessions/{session_id}/scan").json()] == [
        "lenze-8400-motec-ethercat"]
    compared = demo_api.post(f"/ui/sessions/{session_id}/nodes/1/info/object-list").text
    assert "The device reports 36 objects, the profile lists 36; 35 in both." in compared
    only_device = compared[compared.index('id="only-device"'):compared.index("In the profile, not on the device")]
    assert "0x2100" in only_device and "Vendor diagnosis word" in only_device and "VAR" in only_device
    only_profile = compared[compared.index('id="only-profile"'):]
    assert "0x1C33" in only_profile and "0x2100" not in only_profile
    listed = demo_api.get(f"/api/sessions/{session_id}/nodes/1/object-list").json()
    assert (listed["device_count"], listed["profile_count"], listed["common"]) == (36, 36, 35)
    assert [(o["index"], o["name"], o["kind"]) for o in listed["only_device"]] == [
        (0x2100, "Vendor diagnosis word", "VAR")]
    assert [(o["index"], o["ref"]) for o in listed["only_profile"]] == [(0x1C33, "0x1C33")]

    changed_unit.slaves[1001].server.dictionary = None  # a slave without the SDO information service
    refused = demo_api.post(f"/ui/sessions/{session_id}/nodes/1/info/object-list")
    assert refused.status_code >= 400 and "does not offer the SDO information service" in refused.text

    can = demo_api.post("/ui/sessions/demo-plant/nodes/5/info/object-list")
    assert can.status_code >= 400 and "the SDO information service is CoE" in can.text
    problem = demo_api.get("/api/sessions/demo-plant/nodes/5/object-list")
    assert problem.status_code == 409 and problem.headers["content-type"] == "application/problem+json"
    assert "CoE" in problem.json()["detail"]
    assert "Read object list from device" not in demo_api.get("/ui/sessions/demo-plant/nodes/5/tabs/info").text


def _control_until(api: TestClient, state: str, timeout_s: float = 8.0) -> dict[str, Any]:
    return wait_for_value(lambda: (status := api.get(f"{NODE}/control").json())["state"] == state and status,
                          timeout_s, f"the EtherCAT unit in state {state}")


@pytest.mark.usefixtures("patient_guard")  # the flow; the lapse is the next test
def test_the_control_tab_drives_the_unit_over_coe_with_confirmation_and_keepalive(demo_api: TestClient) -> None:
    status = _control_until(demo_api, "ready")
    assert status["family"] == "lenze8400" and status["status_ref"] == "C13850/1"
    assert status["control_bits"][8]["name"] == "SetCInh (controller inhibit)"
    assert demo_api.post(f"{NODE}/control/commands/switch_on").json()["state"] == "switched_on"
    refused = confirmed(demo_api, "POST", f"{NODE}/control/commands/enable_operation", json={"confirm": 2})
    assert refused.status_code == 428 and "node 1" in refused.json()["detail"]  # the wrong node is named
    enabled = confirmed(demo_api, "POST", f"{NODE}/control/commands/enable_operation", json={"confirm": 1}).json()
    assert enabled["state"] == "operation_enabled" and enabled["armed"]
    assert demo_api.put(f"{NODE}/control/setpoint", json={"value": 300}).status_code == 428
    moving = confirmed(demo_api, "PUT", f"{NODE}/control/setpoint", json={"value": 300, "confirm": 1}).json()
    assert moving["armed"] and demo_api.get(f"{NODE}/parameters/C00876/2").json()["raw"] == round(300 * 16384 / 1500)
    speed = wait_for_value(lambda: next(a["value"] for a in demo_api.get(f"{NODE}/control/actuals").json()
                                        if a["ref"] == "C13850/2") or None, 8, "the actual speed (C13850/2)")
    assert 0 < speed <= 300
    # the control word itself, written on the Parameters tab, is a moving write too
    assert demo_api.put(f"{NODE}/parameters/C00876/1", json={"raw": 0x0009}).status_code == 428
    assert demo_api.post(f"{NODE}/control/keepalive").json()["armed"]
    stopped = demo_api.post(f"{NODE}/control/commands/disable_voltage").json()
    assert stopped["state"] == "ready" and not stopped["armed"]


def test_a_lost_keepalive_quick_stops_the_ethercat_unit(demo_api: TestClient) -> None:
    _control_until(demo_api, "ready")
    demo_api.post(f"{NODE}/control/commands/switch_on")
    with demo_api.websocket_connect(f"/ws/sessions/{SESSION}/nodes/1/control") as socket:
        confirmed(demo_api, "POST", f"{NODE}/control/commands/enable_operation", json={"confirm": 1})
        message = socket.receive_json()
        while message["status"]["state"] != "operation_enabled":
            socket.send_json({"cmd": "keepalive"})
            message = socket.receive_json()
        socket.send_json({"cmd": "keepalive"})
    status = wait_for_value(lambda: (s := demo_api.get(f"{NODE}/control").json())["last_trip"] and s, 8, "the trip")
    assert "disconnected" in status["last_trip"] and not status["armed"]
    assert wait_for_value(lambda: demo_api.get(f"{NODE}/parameters/C00876/1").json()["raw"] & 0x0004, 8,
                          "quick stop (bit 2) in the control word C00876/1")  # written just after the trip's record
    assert wait_for_value(lambda: demo_api.get(f"{NODE}/control").json()["status_bits"][4]["set"], 8,
                          "QuickStopIsActive in the status word C13850/1")


def _esm(api: TestClient, command: str) -> None:
    answer = confirmed(api, "POST", f"{NODE}/nmt", json={"command": command, "confirm": 1})
    assert answer.status_code == 200, answer.text


def test_the_pdo_tab_reads_the_assignment_and_the_mappings_over_coe(demo_api: TestClient) -> None:
    assigned = {a["index"]: a for a in demo_api.get(f"{NODE}/pdos/assignment").json()}
    assert sorted(assigned) == [0x1C12, 0x1C13]
    assert [p["mapping_index"] for p in assigned[0x1C12]["pdos"]] == [0x1600]
    assert [p["mapping_index"] for p in assigned[0x1C13]["pdos"]] == [0x1A00]
    assert not assigned[0x1C12]["writable"] and assigned[0x1C12]["sync_manager"] == 2
    unit = demo_api.app.state.drivebench.gateways[SESSION].slaves[1001]  # type: ignore[attr-defined]
    count = unit.store.get(0x1600, 0)
    rx = assigned[0x1C12]["pdos"][0]
    assert len(rx["entries"]) == count and rx["max_entries"] == 8
    tab = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/pdo").text
    assert 'id="ecat-assign-rpdo"' in tab and 'id="ecat-pdo-tpdo1"' in tab
    tx_card = tab[tab.index('id="ecat-pdo-tpdo1"'):]
    assert "0x1A00" in tx_card and "Write mapping" not in tx_card  # the manual names nothing to map into it
    assert "Nothing to map: the profile marks no object as mappable into 0x1A00." in tx_card
    assert "no code of the Communication Unit carries the PDO_MAP_TX attribute" in tx_card
    card = tab[tab.index('id="ecat-pdo-rpdo1"'):tab.index('id="ecat-assign-tpdo"')]
    assert "0x1600" in card and "Write mapping" in card and "COB-ID" not in card and "Transmission type" not in card
    for entry in rx["entries"]:
        assert entry["ref"] in card and entry["name"] in card


def test_a_mapping_is_written_in_pre_operational_and_refused_in_safe_operational(demo_api: TestClient) -> None:
    words = [(0x5C93, 1), (0x5C93, 2)]  # C00876/1 and /2, the manual's mapping example 0x5C930110 and the next word
    assert [(m["index"], m["subindex"]) for m in demo_api.get(f"{NODE}/pdos/mappable/rpdo").json()] == words
    _esm(demo_api, "pre-operational")
    done = demo_api.put(f"{NODE}/pdos/mapping/rpdo/1", json={"entries": words})
    assert done.status_code == 200, done.text
    assert [(s["step"].split(":")[0], s["value"]) for s in done.json()["steps"]] == [
        ("disable mapping (count 0)", "0x00"), ("entry 1", "0x5C930110"), ("entry 2", "0x5C930210"),
        ("enable mapping (count 2)", "0x02")]
    unit = demo_api.app.state.drivebench.gateways[SESSION].slaves[1001]  # type: ignore[attr-defined]
    assert [unit.store.get(0x1600, sub) for sub in (0, 1, 2)] == [2, 0x5C930110, 0x5C930210]
    rx = {a["index"]: a for a in demo_api.get(f"{NODE}/pdos/assignment").json()}[0x1C12]["pdos"][0]
    assert [(e["index"], e["subindex"], e["ref"]) for e in rx["entries"]] == [
        (0x5C93, 1, "C00876/1"), (0x5C93, 2, "C00876/2")] and rx["length_bytes"] == 4

    _esm(demo_api, "stop")  # Safe-Operational
    refused = demo_api.put(f"{NODE}/pdos/mapping/rpdo/1", json={"entries": words[:1]})
    assert refused.status_code == 409 and refused.headers["content-type"] == "application/problem+json"
    problem = refused.json()
    assert problem["type"] == "/problems/mapping-refused-in-state" and problem["status"] == 409
    assert problem["detail"].startswith("RxPDO 0x1600: step 'disable mapping (count 0)' refused (0x08000022 ")
    assert problem["steps"][-1]["ok"] is False and problem["pdo"]["mapping_index"] == 0x1600
    assert "0x08000022" in problem["detail"] and "nothing was changed" in problem["detail"]
    assert "Due to the current device state" in problem["detail"]
    assert "Pre-Operational" in problem["rule"]
    page = demo_api.post(f"/ui/sessions/{SESSION}/nodes/1/pdo/ethercat/rpdo/1/apply",
                         data={"entries": f"0x{words[0][0]:04X}.{words[0][1]}"})
    assert page.status_code == 409 and "0x08000022" in page.text and "Take the slave to Pre-Operational" in page.text
    rx = {a["index"]: a for a in demo_api.get(f"{NODE}/pdos/assignment").json()}[0x1C12]["pdos"][0]
    assert [(e["index"], e["subindex"]) for e in rx["entries"]] == words  # unchanged


def test_the_txpdo_mapping_is_configurable_but_the_manual_names_nothing_to_map(demo_api: TestClient) -> None:
    assert demo_api.get(f"{NODE}/pdos/mappable/tpdo").json() == []
    tx = {a["index"]: a for a in demo_api.get(f"{NODE}/pdos/assignment").json()}[0x1C13]["pdos"][0]
    assert not tx["fixed_mapping"] and tx["max_entries"] == 10  # the manual: input objects 1 ... 10, RW
    assert any("PDO_MAP_TX" in note for note in tx["notes"])
    _esm(demo_api, "pre-operational")
    refused = demo_api.put(f"{NODE}/pdos/mapping/tpdo/1", json={"entries": [[0x29E5, 1]]})  # C13850/1: R only
    assert refused.status_code == 422 and refused.json()["detail"] == (
        "C13850/1 (All words from drive to master: 1st word) cannot be mapped into TxPDO 0x1A00: the profile does "
        "not list it as PDO-mappable (what this PDO carries is read from the device).")


def test_a_mapping_the_profile_forbids_is_422_in_ethercat_words_and_nothing_is_sent(demo_api: TestClient) -> None:
    _esm(demo_api, "pre-operational")
    unit = demo_api.app.state.drivebench.gateways[SESSION].slaves[1001]  # type: ignore[attr-defined]
    before = [unit.store.get(0x1600, sub) for sub in range(3)]
    not_mappable = demo_api.put(f"{NODE}/pdos/mapping/rpdo/1", json={"entries": [[0x5FD8, 1]]})  # C00039/1
    assert not_mappable.status_code == 422 and not_mappable.json()["type"] == "/problems/invalid-value"
    assert not_mappable.json()["detail"] == (
        "C00039/1 (Fixed setpoint: Fixed_Setpoint_1) cannot be mapped into RxPDO 0x1600: the profile does not list "
        "it as PDO-mappable and writable (what this PDO carries is written into the device).")
    too_many = demo_api.put(f"{NODE}/pdos/mapping/rpdo/1", json={"entries": [[0x5C93, 1]] * 9})
    assert too_many.status_code == 422
    assert too_many.json()["detail"] == "RxPDO 0x1600 takes at most 8 mapping entries; 9 were given."
    missing = demo_api.put(f"{NODE}/pdos/mapping/rpdo/2", json={"entries": []})
    assert missing.status_code == 404 and "has no RxPDO 0x1601 in its profile" in missing.json()["detail"]
    for problem in (not_mappable, too_many, missing):
        assert "RPDO" not in problem.text and "TPDO" not in problem.text
    assert [unit.store.get(0x1600, sub) for sub in range(3)] == before
    canopen = demo_api.put("/api/sessions/demo-plant/nodes/3/pdos/mapping/rpdo/5", json={"entries": [[0x6040, 0]]})
    assert canopen.status_code == 409 and canopen.json()["detail"] == (
        "Session demo-plant is not an EtherCAT session: its PDOs have COB-IDs (PDO tab).")


@pytest.fixture
def strict_unit(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    """An 8400 motec EtherCAT unit whose firmware maps fewer words than the shipped profile says: C00876/2 is not
    mappable on it (the slave refuses it with 0x06040041)."""
    shipped = registry.get("lenze-8400-motec-ethercat")
    parameters = [p.model_copy(update={"pdo_mappable": False}) if p.ref == "C00876/2" else p
                  for p in shipped.parameters]
    server = GatewayServer([SimulatedSlave(shipped.model_copy(update={"parameters": parameters}), 1001, 0)]).start()
    yield server
    server.stop()


def test_each_failed_mapping_gets_its_own_status_and_problem_type(demo_api: TestClient,
                                                                  strict_unit: GatewayServer) -> None:
    opened = demo_api.post("/api/sessions", json={"bus": strict_unit.spec, "name": "Strict"})
    assert opened.status_code == 201, opened.text
    node = f"/api/sessions/{opened.json()['id']}/nodes/1"
    assert demo_api.post(f"/api/sessions/{opened.json()['id']}/scan").status_code == 200
    words = [[0x5C93, 1], [0x5C93, 2]]
    refused = demo_api.put(f"{node}/pdos/mapping/rpdo/1", json={"entries": words})  # the slave: not C00876/2
    assert refused.status_code == 422, refused.text
    problem = refused.json()
    assert problem["type"] == "/problems/invalid-mapping" and problem["title"] == "PDO mapping refused by the slave"
    assert "step 'entry 2: C00876/2 Process data input words: Word 2' refused (0x06040041 " in problem["detail"]
    assert problem["detail"].endswith("it reads back with 0 entries.") and problem["pdo"]["entries"] == []

    strict_unit.slaves[1001].request_state(1)  # another master tool took it to Init: no mailbox
    silent = demo_api.put(f"{node}/pdos/mapping/rpdo/1", json={"entries": words[:1]})
    assert silent.status_code == 504, silent.text
    problem = silent.json()
    assert problem["type"] == "/problems/mapping-unanswered" and "did not answer" in problem["detail"]
    assert problem["detail"].endswith("nothing was changed.") and len(problem["steps"]) == 1


def test_a_fixed_mapping_is_said_in_words_on_the_tab_and_refused_with_422(
        demo_api: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path)  # the upload stays out of the repository
    give_changed_profile(demo_api, SESSION, 1, "lenze-8400-motec-ethercat", "ethercat-fixed-rxpdo",
                         {("0x1600", None): {"access": "ro"}})
    tab = demo_api.get(f"/ui/sessions/{SESSION}/nodes/1/pdo").text
    card = tab[tab.index('id="ecat-pdo-rpdo1"'):tab.index('id="ecat-assign-tpdo"')]
    assert "Fixed mapping: the entries of 0x1600 are read-only in this device's profile (manual)" in card
    assert "Write mapping" not in card
    refused = demo_api.put(f"{NODE}/pdos/mapping/rpdo/1", json={"entries": [[0x5C93, 1]]})
    assert refused.status_code == 422 and refused.json()["detail"] == (
        "The mapping of RxPDO 0x1600 is fixed on this device (its entries are read-only in the profile).")


@pytest.fixture
def master_without_diagnosis(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    """A gateway whose master has no diagnosis objects 0xA000 + n (it aborts their reads with 0x06020000)."""
    unit = SimulatedSlave(registry.get("lenze-8400-motec-ethercat"), 1001, 0, name="Plain master unit")
    server = GatewayServer([unit], diagnosis=False).start()
    yield server
    server.stop()


def test_a_master_without_diagnosis_objects_leaves_the_segment_usable(
        demo_api: TestClient, master_without_diagnosis: GatewayServer) -> None:
    opened = demo_api.post("/api/sessions", json={"bus": master_without_diagnosis.spec, "name": "Plain master"})
    assert opened.status_code == 201, opened.text
    session_id = opened.json()["id"]
    nodes = demo_api.get(f"/api/sessions/{session_id}/nodes").json()
    assert [(n["node_id"], n["station"], n["profile_id"], n["nmt_state"]) for n in nodes] == [
        (1, 1001, "lenze-8400-motec-ethercat", "Unknown")]  # AL state unknown, the slave still listed
    assert "Slave list not read" not in demo_api.get("/").text
    assert demo_api.get(f"/api/sessions/{session_id}/nodes/1/parameters/C00039/1").json()["display"] == "40.00 %"
    assert [n["node_id"] for n in demo_api.post(f"/api/sessions/{session_id}/scan").json()] == [1]
