"""PDO REST API, PDO tab routes and the process-data websocket against the demo plant (node 3 MICROMASTER 440,
node 5 8400 motec, node 12 8200 vector): rejections before anything is sent, apply with its step report, DCF
export, live decode of a TPDO after a value change in the simulator, RPDO sending that reaches the drive."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.simulator.plant import Plant
from tests.confirming import confirmed
from tests.conftest import wait_until

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)
SEND = {"confirm": "3", "keepalive": "false", "reason": "test without a browser"}  # RPDO form fields, as above

API = "/api/sessions/demo-plant/nodes"
UI = "/ui/sessions/demo-plant/nodes"


def _plant(client: TestClient) -> Plant:
    plant: Plant = client.app.state.drivebench.plants["demo-plant"]  # type: ignore[attr-defined]
    return plant


def test_list_names_the_mapping_and_offers_vendor_codes(client: TestClient) -> None:
    pdos = client.get(f"{API}/12/pdos").json()
    rpdo1 = next(p for p in pdos if (p["direction"], p["number"]) == ("rpdo", 1))
    assert [e["ref"] for e in rpdo1["entries"]] == ["C1822/1", "C1822/2", "C1822/3"]
    assert rpdo1["entries"][0]["name"].startswith("AIF-IN process input data")
    mappable = client.get(f"{API}/12/pdos/mappable/tpdo").json()
    assert [m["ref"] for m in mappable] == ["C1823/1", "C1823/2", "C1823/3"], "AIF mode 3: words 1...3"
    motec = {m["ref"] for m in client.get(f"{API}/5/pdos/mappable/tpdo").json()}
    assert {"C00868/1", "C00868/8"} <= motec
    mm_tpdo1 = client.get(f"{API}/3/pdos/tpdo/1").json()
    assert mm_tpdo1["fixed_mapping"] and mm_tpdo1["entries"][0]["name"] == "Status word"


def _pdo_objects(client: TestClient, node_id: int) -> dict[tuple[int, int], object]:
    """The node's PDO communication and mapping objects (the drive model moves its status word by itself)."""
    snapshot = _plant(client).nodes[node_id].store.snapshot()
    return {key: value for key, value in snapshot.items() if 0x1400 <= key[0] <= 0x1BFF}


def test_over_length_and_non_mappable_are_refused_before_sending(client: TestClient) -> None:
    before = _pdo_objects(client, 3)
    too_long = {"entries": [[0x6040, 0], [0x6042, 0], [0x2802, 3], [0x2802, 4], [0x6071, 0]]}
    answer = client.put(f"{API}/3/pdos/rpdo/5", json=too_long)
    assert answer.status_code == 422
    assert answer.json()["detail"] == "RPDO5 takes at most 4 mapping entries; 5 were given."
    not_mappable = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6046, 1]]})
    assert not_mappable.status_code == 422 and not_mappable.json()["detail"] == (
        "0x6046.1 (vl velocity min max amount: vl velocity min amount) cannot be mapped into RPDO5: the profile does "
        "not list it as PDO-mappable and writable (what this PDO carries is written into the device).")
    read_only = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6041, 0]]})
    assert read_only.status_code == 422, "a read-only object cannot go into an RPDO"
    assert read_only.json()["detail"].startswith("0x6041 (Status word) cannot be mapped into RPDO5: ")
    not_readable = client.put(f"{API}/3/pdos/tpdo/5", json={"entries": [[0x6046, 1]]})
    assert not_readable.status_code == 422 and not_readable.json()["detail"].endswith(
        "cannot be mapped into TPDO5: the profile does not list it as PDO-mappable (what this PDO carries is read "
        "from the device).")
    fixed = client.put(f"{API}/3/pdos/rpdo/1", json={"entries": [[0x6040, 0]]})
    assert fixed.status_code == 422 and fixed.json()["detail"] == (
        "The mapping of RPDO1 is fixed on this device (its entries are read-only in the profile).")
    wrong_order = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6071, 0], [0x2802, 3]]})
    assert wrong_order.status_code == 422 and "mapping sequence" in wrong_order.json()["detail"]
    eight_words = {"entries": [[0x58E0, 1], [0x58E0, 2], [0x58E0, 3], [0x58E0, 1], [0x58E0, 2]]}
    assert client.put(f"{API}/12/pdos/tpdo/1", json=eight_words).status_code == 422
    ui = client.post(f"{UI}/3/pdo/rpdo/5/apply", data={"entries": "0x6046.1", "valid": "1"})
    assert ui.status_code == 422
    assert _pdo_objects(client, 3) == before


def test_a_mapping_longer_than_a_can_frame_is_refused_before_sending(client: TestClient) -> None:
    before = _pdo_objects(client, 7)
    positions = {"entries": [[0x6062, 0], [0x6063, 0], [0x6064, 0]]}  # three 32-bit positions: 12 bytes
    answer = client.put(f"{API}/7/pdos/tpdo/1", json=positions)
    assert answer.status_code == 422 and answer.json()["type"] == "/problems/invalid-value"
    assert answer.json()["detail"] == "The mapping needs 12 bytes; a PDO carries at most 8."
    assert _pdo_objects(client, 7) == before


def give_changed_profile(client: TestClient, session_id: str, node_id: int, shipped_id: str, new_id: str,
                         changes: dict[tuple[str, int | None], dict[str, Any]]) -> None:
    """Upload a copy of a shipped profile with some objects changed (``changes``: (index, subindex or None for each
    subindex) -> fields) as ``new_id`` and give it to the node. The caller points ``settings.user_profiles_dir`` to
    a temporary directory, so that the upload stays out of the repository."""
    profile = json.loads((settings.profiles_dir / f"{shipped_id}.json").read_text())
    profile["id"] = new_id
    profile["objects"] = [{**entry, **changes.get((entry["index"], entry.get("subindex")), {}),
                           **changes.get((entry["index"], None), {})} for entry in profile["objects"]]
    assert client.post("/api/profiles", files={"file": (f"{new_id}.json", json.dumps(profile).encode())}
                       ).status_code == 201
    assert client.post(f"/api/sessions/{session_id}/nodes", json={"node_id": node_id, "profile_id": new_id}
                       ).json()["profile_id"] == new_id


def test_a_transmission_type_the_profile_forbids_is_refused_before_sending(
        client: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A servo whose manual permits only some types on TPDO1 and none above 240 on TPDO2 (uploaded profile)."""
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path)
    give_changed_profile(client, "demo-plant", 7, "generic-cia402-servo", "servo-strict-transmission", {
        ("0x1800", 2): {"selection": {"1": "every SYNC", "255": "event-driven (device profile)"}},
        ("0x1801", 2): {"max": 240}})
    before = _pdo_objects(client, 7)
    status = {"entries": [[0x6041, 0]], "transmission_type": 254}
    refused = client.put(f"{API}/7/pdos/tpdo/1", json=status)
    assert refused.status_code == 422 and refused.json()["detail"] == (
        "Transmission type 254 is not permitted for this device; its manual allows 1 (every SYNC), "
        "255 (event-driven (device profile)).")
    above = client.put(f"{API}/7/pdos/tpdo/2", json={**status, "transmission_type": 250})
    assert above.status_code == 422
    assert above.json()["detail"] == "Transmission type 250 is above the device's maximum 240."
    assert _pdo_objects(client, 7) == before


def test_failed_apply_reports_the_step_and_leaves_the_pdo_disabled(client: TestClient) -> None:
    """The drive refuses the torque setpoint mid-sequence (as a MICROMASTER 420 would: 6071 is 440-only)."""
    from drivebench.simulator.store import Abort

    store = _plant(client).nodes[3].store

    def refuse_torque(index: int, sub: int, raw: object) -> None:
        if index == 0x1604 and raw == 0x60710010:
            raise Abort(0x06040041)

    store.add_write_check(refuse_torque)
    answer = client.post(f"{UI}/3/pdo/rpdo/5/apply", data={"entries": "0x6040.0,0x6071.0", "valid": "1",
                                                           "cob_id": "0x303"})
    assert answer.status_code == 502 and answer.headers["X-PDO-Report"] == "failed"
    assert "0x06040041" in answer.text and "left disabled" in answer.text
    assert store.get(0x1404, 1) & 0x80000000, "RPDO5 stays invalid"


def test_apply_then_live_tpdo_decode_over_the_websocket(client: TestClient) -> None:
    """TPDO5 of the MICROMASTER carries the status word and the free object 0x2803.3 (P2051.2, a value the drive
    model leaves alone); a change of that value in the simulator arrives decoded over the websocket."""
    sim = _plant(client).nodes[3]
    report = client.put(f"{API}/3/pdos/tpdo/5", json={"entries": [[0x6041, 0], [0x2803, 3]],
                                                      "transmission_type": 255})
    assert report.status_code == 200, report.text
    body = report.json()
    assert body["ok"] and [s["step"].split(" ")[0] for s in body["steps"]][:2] == ["disable", "disable"]
    assert body["pdo"]["length_bytes"] == 4 and body["pdo"]["valid"]
    confirmed(client, "POST", f"{API}/3/nmt", json={"command": "start", "confirm": 3, **NO_BROWSER})
    with client.websocket_connect("/ws/sessions/demo-plant/nodes/3/process-data") as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello"
        tpdo5 = next(p for p in hello["pdos"] if p["direction"] == "tpdo" and p["number"] == 5)
        assert [s["ref"] for s in tpdo5["signals"]] == ["0x6041", "0x2803.3"]
        assert wait_until(lambda: sim.state.name == "OPERATIONAL")
        sim.store.set(0x2803, 3, -1234)
        deadline = time.monotonic() + 10
        found = None
        while time.monotonic() < deadline and found is None:
            message = ws.receive_json()
            for sample in message.get("samples", []):
                free = next(s for s in sample["signals"] if s["ref"] == "0x2803.3")
                if sample["cob_id"] == 0x283 and free["value"] == -1234:
                    found = sample
        assert found is not None, "no TPDO5 with the new value arrived"
        assert found["data"].endswith("2E FB"), "INTEGER16 -1234 little-endian in bytes 2...3"
        assert found["signals"][1]["bit_offset"] == 16


def test_rpdo_send_reaches_the_drive_and_dcf_holds_the_mapping(client: TestClient) -> None:
    sim = _plant(client).nodes[3]
    applied = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6040, 0], [0x6042, 0]]})
    assert applied.status_code == 200, applied.text
    client.get(f"{UI}/3/pdo")  # reads the mappings the sender packs by
    unconfirmed = client.post(f"{UI}/3/pdo/rpdo/5/send", data={"mode": "once", "v:0x6040": "6"})
    assert unconfirmed.status_code == 428 and "RPDO5" in unconfirmed.text
    early = confirmed(client, "POST", f"{UI}/3/pdo/rpdo/5/send", data={**SEND, "mode": "once", "v:0x6040": "6"})
    assert early.status_code == 200 and "ignores PDOs until it is started" in early.text
    confirmed(client, "POST", f"{API}/3/nmt", json={"command": "start", "confirm": 3, **NO_BROWSER})
    sent = confirmed(client, "POST", f"{UI}/3/pdo/rpdo/5/send",
                     data={**SEND, "mode": "once", "v:0x6040": "6", "v:0x6042": "-750"})
    assert "ignores" not in sent.text
    assert sent.status_code == 200 and "06 00 12 FD" in sent.text
    assert wait_until(lambda: sim.store.get(0x6042, 0) == -750)
    assert sim.store.get(0x6040, 0) == 6
    refused = confirmed(client, "POST", f"{UI}/3/pdo/rpdo/5/send", data={**SEND, "mode": "once", "v:0x6042": "40000"})
    assert refused.status_code == 422, "INTEGER16 range is checked before sending"
    cyclic = confirmed(client, "POST", f"{UI}/3/pdo/rpdo/5/send",
                       data={**SEND, "mode": "cyclic", "client_id": "nobody"})
    assert cyclic.status_code == 409, "cyclic sending needs the live view that owns it"
    dcf = client.get(f"{API}/3/pdos/dcf")
    assert dcf.status_code == 200 and "attachment" in dcf.headers["content-disposition"]
    section = dcf.text.split("[1604sub1]", 1)[1].split("[", 1)[0]
    assert "ParameterValue=0x60400010" in section
    assert "NodeID=3" in dcf.text


def test_sync_producer_puts_sync_on_the_bus(client: TestClient) -> None:
    page = client.post(f"{UI}/3/pdo/sync", data={"period_ms": "20", "on": "1"})
    assert page.status_code == 200 and "on, 20 ms" in page.text
    from drivebench.services.pdos import process_data

    session = client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]
    assert process_data.service(session).sync_period_ms == 20
    off = client.post(f"{UI}/3/pdo/sync", data={"period_ms": "20", "on": ""})
    assert "Start SYNC" in off.text and process_data.service(session).sync_period_ms is None


def _frames(wire: can.BusABC, cob_id: int, seconds: float) -> int:
    """Frames with this COB-ID the wire sees within `seconds`."""
    count, deadline = 0, time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        msg = wire.recv(timeout=left)
        if msg is not None and msg.arbitration_id == cob_id:
            count += 1
    return count


def test_cyclic_rpdo_stops_when_the_live_view_closes(client: TestClient, wire: can.BusABC) -> None:
    from drivebench.services.pdos import process_data

    sim = _plant(client).nodes[3]
    session = client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]
    assert client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6040, 0], [0x2802, 3]]}).status_code == 200
    confirmed(client, "POST", f"{API}/3/nmt", json={"command": "start", "confirm": 3, **NO_BROWSER})
    with client.websocket_connect("/ws/sessions/demo-plant/nodes/3/process-data") as ws:
        owner = ws.receive_json()["client_id"]
        started = confirmed(client, "POST", f"{UI}/3/pdo/rpdo/5/send", data={
            **SEND, "mode": "cyclic", "client_id": owner, "period_ms": "20", "v:0x6040": "6", "v:r2050.2": "-5"})
        assert started.status_code == 200 and "sending every 20 ms" in started.text
        assert wait_until(lambda: sim.store.get(0x2802, 3) == -5)
        assert _frames(wire, 0x303, 0.5) >= 2, "cyclic RPDO5 frames on the wire"
        state = ws.receive_json()
        while state["type"] != "state":
            state = ws.receive_json()
        assert state["cyclic"] == [0x303]
    assert wait_until(lambda: not process_data.service(session).cyclic), "the closed socket's cyclic sends end"
    assert _quiet(wire, 0x303, 0.5, within_s=10), "RPDO5 still on the wire every 20 ms"


def _quiet(wire: can.BusABC, cob_id: int, quiet_s: float, *, within_s: float) -> bool:
    """A stretch of `quiet_s` without this COB-ID comes within `within_s` (a frame in flight may still arrive)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        if _frames(wire, cob_id, quiet_s) == 0:
            return True
    return False
