"""Line addressing through the real HTTP API on the new-line plant (four devices without node ID on the real
python-can virtual bus): fastscan, assign with boot-up, the 428 of the steps that reach every device, the refusal
while a node is enabled or armed, the audit rows."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import can
import canopen
import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.services.users import audit
from drivebench.transport.bus import BusSpec, ObservedBus, open_bus
from drivebench.web.app import create_app
from drivebench.web.state import app_state
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, wait_until
from tests.protocol.cia305_slaves import Cia305Bus, Cia305Device

NEW_LINE = REPO_ROOT / "plants" / "new-line.json"
LSS = "/api/sessions/new-line/lss"


@pytest.fixture
def line_api(app_db_url: str) -> Iterator[TestClient]:
    app = create_app(plant_file=NEW_LINE, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def test_fastscan_needs_the_confirmation_naming_every_device(line_api: TestClient) -> None:
    answer = line_api.post(f"{LSS}/fastscan", json={})
    assert answer.status_code == 428
    problem = answer.json()
    assert problem["confirm_node"] == "all"
    assert problem["confirm_values"]["reaches"] == "all nodes on this bus"
    assert problem["confirm_values"]["then"] == "switch state global (waiting)"
    wrong = line_api.post(f"{LSS}/fastscan", json={"confirm": "all", "confirm_values": {"LSS": "fastscan"}})
    assert wrong.status_code == 428
    for path, body in (("switch-global", {}), ("activate-bit-timing", {"bitrate": 250000}),
                       ("reset-communication", {})):
        refused = line_api.post(f"{LSS}/{path}", json=body)
        assert refused.status_code == 428, path
        assert refused.json()["confirm_node"] == "all"


def test_fastscan_finds_the_four_devices_and_one_is_addressed(line_api: TestClient) -> None:
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    assert found.status_code == 200, found.text
    devices = found.json()["devices"]
    assert sorted(int(device["serial"], 16) for device in devices) == [1001, 2002, 3003, 4004]
    assert found.json()["frames"] > 4 * 33
    pump = next(device for device in devices if int(device["serial"], 16) == 3003)
    assert pump["device"].startswith("MICROMASTER 420/430/440")
    body = {key: pump[key] for key in ("vendor", "product", "revision", "serial")} | {"node_id": 20}
    steps = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert steps.status_code == 200, steps.text
    texts = [step["text"] for step in steps.json()]
    assert all(step["ok"] for step in steps.json()), texts
    assert "node 20 booted (boot-up telegram)" in texts
    nodes = line_api.get("/api/sessions/new-line/nodes").json()
    assert [node["node_id"] for node in nodes] == [20]
    left = line_api.get(LSS).json()["devices"]
    assert len(left) == 3
    rows = audit.entries(session_id="new-line")
    assert any(row.new_value.startswith("assign: serial 0x00000BBB -> node ID 20") for row in rows)


def test_assign_to_a_device_that_is_not_there_says_so(line_api: TestClient) -> None:
    body = {"vendor": "0x1", "product": "0x2", "revision": "0x3", "serial": "0x4", "node_id": 21}
    answer = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert answer.status_code == 502
    assert "in LSS waiting state" in answer.json()["detail"]
    assert answer.headers["content-type"].startswith("application/problem+json")
    bad = confirmed(line_api, "POST", f"{LSS}/assign", json={**body, "serial": "zz"})
    assert bad.status_code == 422


def test_global_steps_are_refused_while_a_node_is_enabled_or_armed(app_db_url: str) -> None:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        started = confirmed(client, "POST", "/api/sessions/demo-plant/nodes/3/nmt",
                            json={"command": "start", "keepalive_s": 10})
        assert started.status_code == 200, started.text
        refused = client.post("/api/sessions/demo-plant/lss/fastscan", json={})
        assert refused.status_code == 409
        assert "refused while node 3 is enabled or armed" in refused.json()["detail"]
        client.post("/api/sessions/demo-plant/nodes/3/nmt", json={"command": "pre-operational"})
        # another master on the bus enables the servo: its status word says so
        network = canopen.Network(can.Bus(interface="virtual", channel=channel))
        network.connect()
        try:
            servo = network.add_node(7, canopen.ObjectDictionary())
            for word in (6, 7, 15):
                servo.sdo.download(0x6040, 0, word.to_bytes(2, "little"))
        finally:
            network.disconnect()
        refused = client.post("/api/sessions/demo-plant/lss/switch-global", json={})
        assert refused.status_code == 409
        assert "node 7 is enabled or armed" in refused.json()["detail"]


def test_a_device_with_a_node_id_moves_to_the_new_one(app_db_url: str, tmp_path: Path) -> None:
    plant = {"name": "Two", "nodes": [{"node_id": 5, "lss": True, "serial": 55, "profile": "generic-cia402-servo",
                                        "heartbeat_ms": 500}]}
    path = tmp_path / "two.json"
    path.write_text(json.dumps(plant), encoding="utf-8")
    app = create_app(plant_file=path, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        assert [node["node_id"] for node in client.get("/api/sessions/two/nodes").json()] == [5]
        body = {"vendor": 0, "product": "0x402001", "revision": "0x10000", "serial": 55, "node_id": 9}
        steps = confirmed(client, "POST", "/api/sessions/two/lss/assign", json=body)
        assert steps.status_code == 200, steps.text
        texts = [step["text"] for step in steps.json()]
        assert "device with serial 0x00000037 selected (its node ID: 5)" in texts
        assert "NMT reset communication sent to its old node ID 5" in texts
        assert "node 9 booted (boot-up telegram)" in texts
        assert [node["node_id"] for node in client.get("/api/sessions/two/nodes").json()] == [9]


def test_a_device_without_a_profile_product_code_is_told_by_what_its_answer_says(line_api: TestClient) -> None:
    """Issue 32: the Lenze profiles carry no product code (their manuals give none), so no profile matches the two
    Lenze units' answers. What the answer tells is shown instead of "unknown device": the vendor's name from the
    profiles with its vendor ID, product code and revision as numbers, the profiles of that vendor, and that they
    carry no product code - never an invented one."""
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    assert found.status_code == 200, found.text
    devices = {int(device["serial"], 16): device for device in found.json()["devices"]}
    conveyor, fan, pump = devices[1001], devices[2002], devices[3003]
    for lenze in (conveyor, fan):
        assert lenze["device"] is None and lenze["vendor_name"] == "Lenze"
        ids = {candidate["id"] for candidate in lenze["candidates"]}
        assert {"lenze-8400-motec-canopen", "lenze-8200-vector-emf2178ib"} <= ids
        assert all(candidate["product_code"] is None for candidate in lenze["candidates"]
                   if candidate["id"] == "lenze-8400-motec-canopen")
        text = lenze["identified"]
        assert text.startswith("Lenze (vendor ID 0x0000003B), product code ") and "revision" in text
        assert "carry no product code" in text and "8400 motec" in text
    assert pump["device"].startswith("MICROMASTER") and pump["profile"] == "siemens-micromaster4-canopen"
    assert pump["candidates"] == []
    assert line_api.get(LSS).json()["devices"][0]["identified"]  # the page's reload shows the same


def test_identify_remote_slave_and_the_identity_inquiry(line_api: TestClient) -> None:
    """Issue 32: identify remote slave (vendor, product, revision and serial ranges) and inquire identity / node ID,
    read-only: no confirmation; the inquiry can select one device first (switch state selective)."""
    pump = {"vendor": "0x06000053", "product": "0x00000002"}
    anyone = line_api.post(f"{LSS}/identify-remote", json=pump)
    assert anyone.status_code == 200, anyone.text
    assert anyone.json()["answered"] and "answered" in anyone.json()["text"]
    other = line_api.post(f"{LSS}/identify-remote", json={**pump, "serial_low": 4000, "serial_high": "0xFFFF"})
    assert other.status_code == 200 and not other.json()["answered"]
    assert other.json()["text"].startswith("No device with vendor 0x06000053")
    backwards = line_api.post(f"{LSS}/identify-remote", json={**pump, "serial_low": 9, "serial_high": 3})
    assert backwards.status_code == 422 and "above its high end" in backwards.json()["detail"]
    nobody = line_api.post(f"{LSS}/inquire", json={})  # no device in configuration state
    assert nobody.status_code >= 400 and "no LSS slave answered inquire identity" in nobody.json()["detail"]

    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    device = next(device for device in found.json()["devices"] if int(device["serial"], 16) == 3003)
    select = {key: device[key] for key in ("vendor", "product", "revision", "serial")}
    inquired = line_api.post(f"{LSS}/inquire", json={"select": select})
    assert inquired.status_code == 200, inquired.text
    answer = inquired.json()
    assert {key: answer[key] for key in select} == select
    assert answer["device"].startswith("MICROMASTER") and answer["active_node_id"] is None
    assert "no node ID (255)" in answer["text"] and "stays in LSS configuration state" in answer["text"]


def test_a_device_that_never_leaves_configuration_state_is_named_with_the_next_step(line_api: TestClient) -> None:
    """Issue 32 item 8: a device whose LSS firmware ignores switch state global (waiting) (the simulator's fault)
    never takes its new node ID. The assign says so - it still answers the LSS inquiry - and what to do, instead of
    only "no boot-up within 5 s"."""
    plant = app_state(line_api.app).plants["new-line"]  # type: ignore[arg-type]
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    plant.lss.by_serial(3003).slave.faults.stays_in_configuration = True
    pump = next(device for device in found.json()["devices"] if int(device["serial"], 16) == 3003)
    body = {key: pump[key] for key in ("vendor", "product", "revision", "serial")} | {"node_id": 20}
    steps = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert steps.status_code == 200, steps.text
    last = steps.json()[-1]
    assert not last["ok"]
    assert "still in LSS configuration state" in last["text"] and "serial 0x00000BBB" in last["text"]
    assert "Power-cycle it: it starts with the node ID it stored." in last["text"]
    plant.lss.by_serial(3003).slave.faults.stays_in_configuration = False
    plant.lss.power_cycle()  # the next step offered: it starts with the stored node ID 20
    assert wait_until(lambda: 20 in plant.nodes, 15)


def test_a_device_stuck_in_configuration_state_since_the_fastscan_is_named(line_api: TestClient) -> None:
    """Issue 32 item 8: the device ignored the fastscan's closing switch state global (waiting), so the assign's
    switch state selective (answered only in waiting state) gets no answer. Not "is the device on this bus?": a
    device still answers the LSS inquiry, so one never left configuration state, and the next step is said."""
    plant = app_state(line_api.app).plants["new-line"]  # type: ignore[arg-type]
    plant.lss.by_serial(3003).slave.faults.stays_in_configuration = True
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    pump = next(device for device in found.json()["devices"] if int(device["serial"], 16) == 3003)
    body = {key: pump[key] for key in ("vendor", "product", "revision", "serial")} | {"node_id": 20}
    refused = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert refused.status_code == 502, refused.text
    detail = refused.json()["detail"]
    assert "still in LSS configuration state" in detail and "Power-cycle the device" in detail, detail


def _assign_all_at(client: TestClient, bitrate: int) -> None:
    found = confirmed(client, "POST", f"{LSS}/fastscan", json={})
    devices = {int(device["serial"], 16): device for device in found.json()["devices"]}
    for node_id, serial in ((21, 1001), (22, 2002), (23, 3003), (24, 4004)):
        body = {key: devices[serial][key] for key in ("vendor", "product", "revision", "serial")}
        steps = confirmed(client, "POST", f"{LSS}/assign", json=body | {"node_id": node_id, "bitrate": bitrate})
        assert steps.status_code == 200, steps.text
        assert steps.json()[-1]["ok"], steps.text


def _wire_at(channel: str, bitrate: int) -> ObservedBus:
    """An adapter of its own on the plant's virtual bus (another tool's), opened at ``bitrate``."""
    return open_bus(BusSpec(interface="virtual", channel=channel, bitrate=bitrate))


def _device_type(wire: ObservedBus, node_id: int) -> bytes | None:
    """SDO upload of 0x1000 (expedited) to ``node_id``: its answer, None when none comes."""
    wire.send(can.Message(arbitration_id=0x600 + node_id, data=bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
                          is_extended_id=False))
    deadline = time.monotonic() + 2.0
    while (left := deadline - time.monotonic()) > 0:
        msg = wire.recv(left)
        if msg is not None and msg.arbitration_id == 0x580 + node_id:
            return bytes(msg.data)
    return None


def test_a_bit_rate_switch_moves_the_adapter_and_names_the_device_left_behind(app_db_url: str,
                                                                               tmp_path: Path) -> None:
    """Issue 32 items 1 and 8: the four devices get 250 kbit/s configured, the pump's LSS firmware ignores activate
    bit timing (set in the plant file). After the switch the session's own adapter runs at 250 kbit/s, the three
    that followed answer there (LSS and SDO), and the pump - silent at 250 kbit/s, still answering at 500 kbit/s -
    is named with the next step."""
    plant = json.loads(NEW_LINE.read_text(encoding="utf-8"))
    plant["nodes"][2]["lss_faults"] = {"ignores_activate_bit_timing": True}
    channel = fresh_channel()
    path = tmp_path / "new-line.json"
    path.write_text(json.dumps(plant), encoding="utf-8")
    app = create_app(plant_file=path, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        _assign_all_at(client, 250_000)
        assert confirmed(client, "POST", f"{LSS}/switch-global", json={"configuration": True}).status_code == 204
        switched = confirmed(client, "POST", f"{LSS}/activate-bit-timing", json={"bitrate": 250000,
                                                                                "switch_delay_ms": 20})
        assert switched.status_code == 200, switched.text
        answer = switched.json()
        assert answer["adapter_bitrate"] == 250000 and answer["old_bitrate"] == 500000 and answer["checked"] == 4
        assert sorted(int(device["serial"], 16) for device in answer["followed"]) == [1001, 2002, 4004], answer["text"]
        assert [(int(device["serial"], 16), device["at_old_rate"]) for device in answer["left_behind"]] == [
            (3003, True)]
        text = answer["text"]
        assert text.startswith("This session's adapter now runs at 250 kbit/s. 1 of 4 devices did not follow to "
                               "250 kbit/s: serial 0x00000BBB does not answer at 250 kbit/s."), text
        assert "Serial 0x00000BBB still answers at 500 kbit/s" in text and "Power-cycle it" in text
        assert "stays at 500" not in text
        session = client.get("/api/sessions/new-line").json()
        assert session["bitrate"] == 250000 and session["bus"].endswith("@250000")
        assert client.get("/api/sessions/new-line/monitor").json()["bitrate"] == 250000, "bus load at the new rate"
        # through the session's adapter, at the new rate: the followers answer, the pump does not
        for node_id in (21, 22, 24):
            read = client.get(f"/api/sessions/new-line/nodes/{node_id}/parameters/0x1000")
            assert read.status_code == 200, read.text
        assert client.get("/api/sessions/new-line/nodes/23/parameters/0x1000").status_code >= 400
        # another adapter on the wire: the pump answers at 500 kbit/s only, the others at 250 kbit/s only
        with _wire_at(channel, 500_000) as old, _wire_at(channel, 250_000) as new:
            assert _device_type(old, 23) is not None and _device_type(new, 23) is None
            assert _device_type(new, 21) is not None and _device_type(old, 21) is None


def test_the_lss_faults_are_switched_through_the_simulator_api(line_api: TestClient) -> None:
    """Issue 32: the simulator's LSS faults without Python - next to the SDO faults of the simulator API, by the
    device's serial number (it has no node ID yet). A device that never leaves configuration state is then named
    by the assign."""
    url = "/api/sessions/new-line/simulator/lss/3003/faults"
    assert line_api.get(url).json()["active"] == []
    bad = line_api.put(url, json={"stays_in_configuration": True, "wobbles": True})
    assert bad.status_code == 422
    switched = line_api.put(url, json={"stays_in_configuration": True})
    assert switched.status_code == 200, switched.text
    assert switched.json()["serial"] == "0x00000BBB"
    assert switched.json()["active"][0].startswith("ignores switch state global (waiting)")
    assert line_api.get("/api/sessions/new-line/simulator/lss/9999/faults").status_code == 404
    found = confirmed(line_api, "POST", f"{LSS}/fastscan", json={})
    pump = next(device for device in found.json()["devices"] if int(device["serial"], 16) == 3003)
    body = {key: pump[key] for key in ("vendor", "product", "revision", "serial")} | {"node_id": 20}
    refused = confirmed(line_api, "POST", f"{LSS}/assign", json=body)
    assert refused.status_code == 502, refused.text
    assert "still in LSS configuration state" in refused.json()["detail"]
    assert line_api.put(url, json={}).json()["active"] == []


def test_a_bit_rate_switch_with_lss_slaves_that_share_no_code_with_the_simulator(demo_api: TestClient) -> None:
    """Issue 32 items 1 and 9: the same switch against LSS slaves written from CiA 305 alone, each with a controller
    at its own rate: two configured to 250 kbit/s follow, one configured to 500 kbit/s stays. The session's adapter
    follows, the two answer at 250 kbit/s, the third is named as still answering at 500 kbit/s."""
    channel = fresh_channel()
    devices = [Cia305Device(0x1234, 7, 1, 0xA1, timing=3), Cia305Device(0x1234, 7, 1, 0xA2, timing=3),
               Cia305Device(0x1234, 7, 1, 0xB1)]
    slaves = Cia305Bus(channel, devices, bitrate=500_000)
    try:
        opened = demo_api.post("/api/sessions", json={"bus": f"virtual:{channel}@500000", "name": "Independent"})
        assert opened.status_code == 201, opened.text
        lss = f"/api/sessions/{opened.json()['id']}/lss"
        found = confirmed(demo_api, "POST", f"{lss}/fastscan", json={})
        assert found.status_code == 200, found.text
        assert sorted(int(device["serial"], 16) for device in found.json()["devices"]) == [0xA1, 0xA2, 0xB1]
        switched = confirmed(demo_api, "POST", f"{lss}/activate-bit-timing",
                             json={"bitrate": 250000, "switch_delay_ms": 20, "configuration_first": True})
        assert switched.status_code == 200, switched.text
        answer = switched.json()
        assert answer["adapter_bitrate"] == 250000
        assert sorted(int(device["serial"], 16) for device in answer["followed"]) == [0xA1, 0xA2], answer["text"]
        assert [(int(device["serial"], 16), device["at_old_rate"]) for device in answer["left_behind"]] == [
            (0xB1, True)]
        assert "Serial 0x000000B1 still answers at 500 kbit/s" in answer["text"]
        assert [device.rate for device in devices] == [250_000, 250_000, 500_000]
        # waiting: "switch state global" has no answer, so the slaves' thread may take it after the API answered
        assert wait_until(lambda: [device.configuring for device in devices] == [False, False, True]), [
            device.configuring for device in devices]
    finally:
        slaves.shutdown()
