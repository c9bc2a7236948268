"""PDO REST API, PDO tab routes and the process-data websocket against the demo plant (node 3 MICROMASTER 440,
node 5 8400 motec, node 12 8200 vector): rejections before anything is sent, apply with its step report, DCF
export, live decode of a TPDO after a value change in the simulator, RPDO sending that reaches the drive."""

from __future__ import annotations

import time
from collections.abc import Callable

from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant

API = "/api/sessions/demo-plant/nodes"
UI = "/ui/sessions/demo-plant/nodes"


def _plant(client: TestClient) -> Plant:
    plant: Plant = client.app.state.drivebench.plants["demo-plant"]  # type: ignore[attr-defined]
    return plant


def _wait(condition: Callable[[], bool], seconds: float = 5.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return condition()


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


def test_over_length_and_non_mappable_are_refused_before_sending(client: TestClient) -> None:
    store = _plant(client).nodes[3].store
    before = store.snapshot()
    too_long = {"entries": [[0x6040, 0], [0x6042, 0], [0x2802, 3], [0x2802, 4], [0x6071, 0]]}
    answer = client.put(f"{API}/3/pdos/rpdo/5", json=too_long)
    assert answer.status_code == 422 and "at most 4" in answer.json()["detail"]
    not_mappable = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6046, 1]]})
    assert not_mappable.status_code == 422 and "cannot be mapped" in not_mappable.json()["detail"]
    read_only = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6041, 0]]})
    assert read_only.status_code == 422, "a read-only object cannot go into an RPDO"
    fixed = client.put(f"{API}/3/pdos/rpdo/1", json={"entries": [[0x6040, 0]]})
    assert fixed.status_code == 422 and "fixed" in fixed.json()["detail"]
    wrong_order = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6071, 0], [0x2802, 3]]})
    assert wrong_order.status_code == 422 and "mapping sequence" in wrong_order.json()["detail"]
    eight_words = {"entries": [[0x58E0, 1], [0x58E0, 2], [0x58E0, 3], [0x58E0, 1], [0x58E0, 2]]}
    assert client.put(f"{API}/12/pdos/tpdo/1", json=eight_words).status_code == 422
    ui = client.post(f"{UI}/3/pdo/rpdo/5/apply", data={"entries": "0x6046.1", "valid": "1"})
    assert ui.status_code == 422
    assert store.snapshot() == before


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
    sim = _plant(client).nodes[3]
    report = client.put(f"{API}/3/pdos/tpdo/5", json={"entries": [[0x6041, 0], [0x6044, 0]],
                                                      "transmission_type": 255})
    assert report.status_code == 200, report.text
    body = report.json()
    assert body["ok"] and [s["step"].split(" ")[0] for s in body["steps"]][:2] == ["disable", "disable"]
    assert body["pdo"]["length_bytes"] == 4 and body["pdo"]["valid"]
    client.post(f"{API}/3/nmt", json={"command": "start"})
    with client.websocket_connect("/ws/sessions/demo-plant/nodes/3/process-data") as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello"
        tpdo5 = next(p for p in hello["pdos"] if p["direction"] == "tpdo" and p["number"] == 5)
        assert [s["ref"] for s in tpdo5["signals"]] == ["0x6041", "0x6044"]
        assert _wait(lambda: sim.state.name == "OPERATIONAL" if hasattr(sim, "state") else True)
        sim.store.set(0x6044, 0, 1234)
        deadline = time.monotonic() + 10
        found = None
        while time.monotonic() < deadline and found is None:
            message = ws.receive_json()
            for sample in message.get("samples", []):
                speed = next(s for s in sample["signals"] if s["ref"] == "0x6044")
                if sample["cob_id"] == 0x283 and speed["value"] == 1234:
                    found = speed
        assert found is not None and found["unit"] == "rpm" and found["bit_offset"] == 16


def test_rpdo_send_reaches_the_drive_and_dcf_holds_the_mapping(client: TestClient) -> None:
    sim = _plant(client).nodes[3]
    applied = client.put(f"{API}/3/pdos/rpdo/5", json={"entries": [[0x6040, 0], [0x6042, 0]]})
    assert applied.status_code == 200, applied.text
    client.post(f"{API}/3/nmt", json={"command": "start"})
    client.get(f"{UI}/3/pdo")  # reads the mappings the sender packs by
    sent = client.post(f"{UI}/3/pdo/rpdo/5/send", data={"mode": "once", "v:0x6040": "6", "v:0x6042": "-750"})
    assert sent.status_code == 200 and "06 00 12 FD" in sent.text
    assert _wait(lambda: sim.store.get(0x6042, 0) == -750)
    assert sim.store.get(0x6040, 0) == 6
    refused = client.post(f"{UI}/3/pdo/rpdo/5/send", data={"mode": "once", "v:0x6042": "40000"})
    assert refused.status_code == 422, "INTEGER16 range is checked before sending"
    cyclic = client.post(f"{UI}/3/pdo/rpdo/5/send", data={"mode": "cyclic", "client_id": "nobody"})
    assert cyclic.status_code == 409, "cyclic sending needs the live view that owns it"
    dcf = client.get(f"{API}/3/pdos/dcf")
    assert dcf.status_code == 200 and "attachment" in dcf.headers["content-disposition"]
    section = dcf.text.split("[1604sub1]", 1)[1].split("[", 1)[0]
    assert "ParameterValue=0x60400010" in section
    assert "NodeID=3" in dcf.text


def test_sync_producer_puts_sync_on_the_bus(client: TestClient) -> None:
    page = client.post(f"{UI}/3/pdo/sync", data={"period_ms": "20", "on": "1"})
    assert page.status_code == 200 and "on, 20 ms" in page.text
    from drivebench.services import process_data

    session = client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined]
    assert process_data.service(session).sync_period_ms == 20
    off = client.post(f"{UI}/3/pdo/sync", data={"period_ms": "20", "on": ""})
    assert "Start SYNC" in off.text and process_data.service(session).sync_period_ms is None
