"""The comparison with the factory setting and undo of one write (issue 30 item 5), over the HTTP API on the demo
plant (virtual CAN bus, simulated nodes) and on a plant whose device has only an uploaded EDS.

Node 5 (8400 motec) starts at its profile's defaults; the one setting the plant file itself changes is the producer
heartbeat time 0x1017 (``heartbeat_ms: 500``), so the comparison of a fresh node 5 lists exactly that."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import fresh_channel, wait_until

SESSION = "demo-plant"
NODE = f"/api/sessions/{SESSION}/nodes"


def _compare(api: TestClient, node: int, read: str = "missing", session: str = SESSION) -> dict[str, Any]:
    answer = api.get(f"/api/sessions/{session}/nodes/{node}/changed-from-default", params={"read": read})
    assert answer.status_code == 200, answer.text
    found: dict[str, Any] = answer.json()
    return found


def _changed(found: dict[str, Any]) -> dict[str, tuple[str, str]]:
    return {row["ref"]: (row["value"]["display"], row["factory"]) for row in found["changed"]}


def _audit(api: TestClient, node: int) -> list[dict[str, Any]]:
    answer = api.get("/api/audit", params={"node_id": node})
    assert answer.status_code == 200, answer.text
    rows: list[dict[str, Any]] = answer.json()
    return rows


def _read(api: TestClient, node: int, ref: str) -> dict[str, Any]:
    answer = api.get(f"{NODE}/{node}/parameters/{ref}")
    assert answer.status_code == 200, answer.text
    value: dict[str, Any] = answer.json()
    return value


def _write(api: TestClient, node: int, ref: str, value: object) -> dict[str, Any]:
    answer = confirmed(api, "PUT", f"{NODE}/{node}/parameters/{ref}", json={"value": value})
    assert answer.status_code == 200, answer.text
    result: dict[str, Any] = answer.json()
    assert result["verified"] is True
    return result


def test_changed_from_default_lists_exactly_the_settings_written(demo_api: TestClient) -> None:
    fresh = _compare(demo_api, 5)
    assert _changed(fresh) == {"0x1017": ("500 ms", "0 ms")}, "the plant file's heartbeat, nothing else"
    assert fresh["same"] > 50 and not fresh["not_read"]
    _write(demo_api, 5, "C00088", 12.5)
    _write(demo_api, 5, "C00011", 1400)
    changed = _changed(_compare(demo_api, 5, "all"))
    assert changed == {"0x1017": ("500 ms", "0 ms"), "C00088": ("12.50 A", "10.20 A"),
                       "C00011": ("1400 rpm", "1500 rpm")}
    _write(demo_api, 5, "C00011", 1500)  # back to the factory value: no longer listed
    assert set(_changed(_compare(demo_api, 5, "none"))) == {"0x1017", "C00088"}


def test_compare_reads_only_what_it_was_asked_to(demo_api: TestClient) -> None:
    unread = _compare(demo_api, 12, "none")
    assert not unread["changed"] and unread["same"] == 0 and len(unread["not_read"]) > 50
    assert demo_api.get(f"{NODE}/12/changed-from-default", params={"read": "some"}).status_code == 422


@pytest.fixture
def eds_plant(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, app_db_url: str) -> Iterator[TestClient]:
    """Node 9 is a device known only by an uploaded EDS; 0x2000 has no DefaultValue, 0x2001 has 5."""
    user_dir = tmp_path / "user-profiles"
    user_dir.mkdir()
    (user_dir / "minimal-io.eds").write_text(MINIMAL_EDS, encoding="utf-8")
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    plant = tmp_path / "plant.json"
    plant.write_text(json.dumps({"name": "EDS plant", "nodes": [{"node_id": 9, "profile": "minimal-io"}]}),
                     encoding="utf-8")
    with TestClient(create_app(plant_file=plant, plant_bus=f"virtual:{fresh_channel()}@500000",
                               latency="0ms")) as client:
        yield client


def test_an_eds_only_device_lists_settings_without_a_factory_value_apart(eds_plant: TestClient) -> None:
    session = eds_plant.get("/api/sessions").json()[0]["id"]
    found = _compare(eds_plant, 9, session=session)
    assert [row["ref"] for row in found["no_factory_value"]] == ["0x2000"]
    assert found["no_factory_value"][0]["factory"] is None and found["no_factory_value"][0]["value"]["raw"] == 0
    assert not found["changed"]
    answer = eds_plant.put(f"/api/sessions/{session}/nodes/9/parameters/0x2001", json={"value": 7})
    assert answer.status_code == 200, answer.text
    found = _compare(eds_plant, 9, "none", session=session)
    assert [(row["ref"], row["value"]["display"], row["factory"]) for row in found["changed"]] == [("0x2001", "7", "5")]


def test_undo_writes_the_old_value_back_through_the_checked_write(demo_api: TestClient) -> None:
    assert _read(demo_api, 5, "C00088")["display"] == "10.20 A"
    _write(demo_api, 5, "C00088", 12.5)
    record = _audit(demo_api, 5)[0]
    assert (record["ref"], record["old_value"], record["new_value"]) == ("C00088", "10.20 A", "12.50 A")
    answer = demo_api.post(f"/api/audit/{record['id']}/undo")
    assert answer.status_code == 200, answer.text
    undone = answer.json()
    assert undone["verified"] is True and undone["undone"] == record["id"]
    assert undone["read_back"]["display"] == "10.20 A"
    assert _read(demo_api, 5, "C00088")["display"] == "10.20 A"
    newest = _audit(demo_api, 5)[0]
    assert (newest["origin"], newest["old_value"], newest["new_value"], newest["result"]) == (
        f"undo {record['id']}", "12.50 A", "10.20 A", "written")
    assert "C00088" not in _changed(_compare(demo_api, 5, "all"))


def test_undo_of_a_selection_writes_its_number(demo_api: TestClient) -> None:
    assert _read(demo_api, 5, "C00592.1")["raw"] == 0
    _write(demo_api, 5, "C00592.1", 1)
    record = _audit(demo_api, 5)[0]
    assert record["old_value"].startswith("0 = ")
    assert demo_api.post(f"/api/audit/{record['id']}/undo").status_code == 200
    assert _read(demo_api, 5, "C00592.1")["raw"] == 0


def test_undo_is_refused_in_words_without_an_old_value(demo_api: TestClient) -> None:
    _write(demo_api, 5, "C00011", 1400)  # never read before: the record has no old value
    record = _audit(demo_api, 5)[0]
    assert record["old_value"] is None
    answer = demo_api.post(f"/api/audit/{record['id']}/undo")
    assert answer.status_code == 409
    assert answer.headers["content-type"].startswith("application/problem+json")
    assert "has no old value" in answer.json()["detail"]
    assert _read(demo_api, 5, "C00011")["display"] == "1400 rpm", "nothing was written"
    assert demo_api.post("/api/audit/999999/undo").status_code == 404


def test_undo_is_refused_when_the_node_has_another_profile_now(demo_api: TestClient) -> None:
    _read(demo_api, 5, "C00088")
    _write(demo_api, 5, "C00088", 12.5)
    record = _audit(demo_api, 5)[0]
    assert demo_api.post(f"{NODE}", json={"node_id": 5, "profile_id": "generic-cia402-servo"}).status_code == 201
    answer = demo_api.post(f"/api/audit/{record['id']}/undo")
    assert answer.status_code == 409
    assert "generic-cia402-servo" in answer.json()["detail"] and "lenze-8400-motec-canopen" in answer.json()["detail"]
    assert len(_audit(demo_api, 5)) == 1, "nothing was sent"


def test_undo_of_a_moving_write_asks_for_the_confirmation_naming_the_old_value(demo_api: TestClient) -> None:
    old = _read(demo_api, 7, "0x6060")
    _write(demo_api, 7, "0x6060", 3 if old["raw"] != 3 else 1)
    record = _audit(demo_api, 7)[0]
    url = f"/api/audit/{record['id']}/undo"
    asked = demo_api.post(url)
    assert asked.status_code == 428, asked.text
    assert asked.json()["confirm_node"] == 7
    assert list(asked.json()["confirm_values"].values()) == [old["raw"]]
    answer = confirmed(demo_api, "POST", url)
    assert answer.status_code == 200, answer.text
    assert _read(demo_api, 7, "0x6060")["raw"] == old["raw"]
    assert _audit(demo_api, 7)[0]["origin"] == f"undo {record['id']}"


def test_cob_ids_identity_and_words_read_in_hex_amounts_in_decimal(demo_api: TestClient) -> None:
    assert _read(demo_api, 5, "0x1800.1")["display"] == "0x00000185"
    assert _read(demo_api, 5, "0x1200.2")["display"] == "0x00000585"
    assert _read(demo_api, 5, "0x1018.1")["display"] == "0x0000003B"
    assert _read(demo_api, 5, "0x1017")["display"] == "500 ms", "an amount stays decimal with its unit"
    assert _read(demo_api, 5, "0x1800.2")["display"] == "254"
    listed = demo_api.get(f"{NODE}/5/parameters", params={"q": "0x1800.1"}).json()["parameters"][0]
    assert (listed["default"], listed["factory"]) == (None, "0x00000185"), "CiA 301's pre-defined connection set"
    c88 = demo_api.get(f"{NODE}/5/parameters", params={"q": "C00088"}).json()["parameters"][0]
    assert (c88["default"], c88["factory"], c88["unit"]) == (10.2, "10.20 A", "A")
    compared = _compare(demo_api, 5)
    assert "0x1800.1" not in _changed(compared)


def test_a_live_status_word_reads_in_hex_with_its_bit_names(demo_api: TestClient) -> None:
    """TPDO5 of node 3 (MICROMASTER) mapped with the status word 0x6041: each sample gives it in hex beside the
    names of its set bits, a free INTEGER16 (0x2803.3) in decimal only."""
    sim = demo_api.app.state.drivebench.plants[SESSION].nodes[3]  # type: ignore[attr-defined]
    report = demo_api.put(f"{NODE}/3/pdos/tpdo/5", json={"entries": [[0x6041, 0], [0x2803, 3]],
                                                         "transmission_type": 255})
    assert report.status_code == 200, report.text
    confirmed(demo_api, "POST", f"{NODE}/3/nmt", json={"command": "start", "confirm": 3, "keepalive": False,
                                                       "reason": "test without a browser"})
    with demo_api.websocket_connect(f"/ws/sessions/{SESSION}/nodes/3/process-data") as ws:
        assert ws.receive_json()["type"] == "hello"
        assert wait_until(lambda: sim.state.name == "OPERATIONAL")
        sim.store.set(0x2803, 3, -7)
        deadline = time.monotonic() + 10
        found = None
        while time.monotonic() < deadline and found is None:
            for sample in ws.receive_json().get("samples", []):
                if sample["cob_id"] == 0x283 and sample["signals"][1]["value"] == -7:
                    found = sample
        assert found is not None, "no TPDO5 with the new value arrived"
    status, free = found["signals"]
    assert status["hex"] == f"0x{status['raw']:04X}" and status["text"]
    assert free["hex"] is None


MINIMAL_EDS = """[FileInfo]
FileName=minimal-io.eds
FileVersion=1
FileRevision=0
EDSVersion=4.0
Description=Minimal test device

[DeviceInfo]
VendorName=Test vendor
VendorNumber=0x00ABCDEF
ProductName=Minimal EDS device
ProductNumber=0x1
RevisionNumber=0x1
BaudRate_500=1
SimpleBootUpSlave=1
Granularity=8
NrOfRXPDO=0
NrOfTXPDO=0
LSS_Supported=0

[MandatoryObjects]
SupportedObjects=2
1=0x1000
2=0x1001

[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00000000
PDOMapping=0

[1001]
ParameterName=Error register
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=0
PDOMapping=0

[OptionalObjects]
SupportedObjects=1
1=0x1017

[1017]
ParameterName=Producer heartbeat time
ObjectType=0x7
DataType=0x0006
AccessType=rw
DefaultValue=0
PDOMapping=0

[ManufacturerObjects]
SupportedObjects=2
1=0x2000
2=0x2001

[2000]
ParameterName=Output filter
ObjectType=0x7
DataType=0x0006
AccessType=rw
LowLimit=0
HighLimit=1000
PDOMapping=0

[2001]
ParameterName=Output gain
ObjectType=0x7
DataType=0x0006
AccessType=rw
LowLimit=1
HighLimit=100
DefaultValue=5
PDOMapping=0
"""
