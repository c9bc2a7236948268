"""Faults in the manual's words (issue 30 item 4) over the real API on the demo plant: a simulated drive sends its
EMCY on the virtual bus, the server's EMCY consumer decodes the device's own fault number with its profile's
``faults`` section (MICROMASTER F- and A-numbers, Lenze 8400 error numbers), and an enable sent to a MICROMASTER
whose P0700 routes commands to the terminals says why it did nothing."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.device.profiles.scaling import to_raw
from drivebench.simulator.plant import Plant
from tests.confirming import confirmed
from tests.conftest import wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

SESSION = "demo-plant"
MM, MOTEC, VECTOR = 3, 5, 12


def _plant(client: TestClient) -> Plant:
    plants: dict[str, Plant] = client.app.state.drivebench.plants  # type: ignore[attr-defined]
    return plants[SESSION]


def _newest_emcy(client: TestClient, node: int, code: str) -> dict[str, Any]:
    found: dict[str, Any] = {}

    def arrived() -> bool:
        history = client.get(f"/api/sessions/{SESSION}/nodes/{node}/emcy").json()
        if history and history[0]["code"] == code:
            found.update(history[0])
            return True
        return False
    assert wait_until(arrived, 10.0), f"no EMCY {code} from node {node}"
    return found


def _lenze(number: int) -> bytes:
    """The manufacturer-specific bytes of an 8400 motec EMCY: byte 4 reserved, bytes 5...8 the Lenze error number."""
    return b"\x00" + number.to_bytes(4, "little")


def test_micromaster_fault_number_is_decoded_with_the_manuals_text_and_remedy(client: TestClient) -> None:
    drive = _plant(client).nodes[MM]
    drive.raise_emcy(0x7001, 0x01, bytes([70, 0]))  # F0070 as the option module sends it (Table 3-14)
    record = _newest_emcy(client, MM, "0x7001")
    fault = record["fault"]
    assert fault["number"] == 70 and fault["label"] == "F0070"
    assert "P2040" in fault["text"] and "telegram" not in fault["label"]
    assert fault["remedy"].startswith("Check whether the CANopen master has stopped")
    assert "Issue 01/05" in fault["source"] and "Table 7-5" in fault["source"]

    drive.raise_emcy(0x2310, 0x03, bytes([1, 0]))
    overcurrent = _newest_emcy(client, MM, "0x2310")["fault"]
    assert overcurrent["label"] == "F0001" and overcurrent["text"].endswith("overcurrent")
    assert overcurrent["remedy"] is None, "the CANopen manual gives no remedy for F0001: none is made up"
    health = next(s for s in client.get("/api/health/nodes").json() if s["session_id"] == SESSION)
    active = next(n for n in health["nodes"] if n["node_id"] == MM)["active_emcy"]
    assert active["fault"]["label"] == "F0001"


def test_lenze_8400_error_number_is_read_from_bytes_5_to_8_with_its_fields(client: TestClient) -> None:
    drive = _plant(client).nodes[MOTEC]
    drive.raise_emcy(0xF000, 0x01, _lenze(0x11C4000B))  # OC1 with error type WarningLocked
    record = _newest_emcy(client, MOTEC, "0xF000")
    assert record["data"] == "00 0B 00 C4 11", "byte 4 reserved, bytes 5...8 the error number (manual ch. 10.4)"
    fault = record["fault"]
    assert fault["label"] == "OC1" and fault["text"].startswith("Short circuit")
    assert fault["fields"] == ["error type: WarningLocked", "subject area: 452", "error ID: 11"]

    drive.raise_emcy(0x1000, 0x01, _lenze(0x05C4000B))  # the same error set to the type Fault
    same = _newest_emcy(client, MOTEC, "0x1000")["fault"]
    assert same["label"] == "OC1" and same["fields"][0] == "error type: Fault"

    drive.raise_emcy(0xF000, 0x01, _lenze(0x047F0002))
    assert _newest_emcy(client, MOTEC, "0xF000")["fault"]["label"] == "CE04"
    drive.raise_emcy(0x1000, 0x01, _lenze(0x04010203))  # a number the sources did not give
    unknown = _newest_emcy(client, MOTEC, "0x1000")["fault"]
    assert unknown["label"] == "0x04010203" and unknown["text"] is None
    assert unknown["fields"] == ["error type: Fault", "subject area: 1", "error ID: 515"]


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_enable_on_terminal_control_says_why_nothing_moves(client: TestClient) -> None:
    url = f"/api/sessions/{SESSION}/nodes/{MM}/control"
    store = _plant(client).nodes[MM].store
    store.set_ref("P1000", to_raw(store.catalog.resolve("P1000").entry, 6))
    assert wait_until(lambda: client.get(url).json()["state"] == "switch_on_disabled", 8.0)
    assert client.post(url + "/commands/shutdown").json()["command_note"] is None, "shutdown moves nothing"
    enabled = confirmed(client, "POST", url + "/commands/enable_operation", json={})
    assert enabled.status_code == 200, enabled.text
    note = enabled.json()["command_note"]
    assert note is not None and note.startswith("P0700 = 2 (Terminal)") and "set P0700 = 6 for the fieldbus" in note
    assert enabled.json()["state"] != "operation_enabled", "the MICROMASTER ignores the fieldbus's control word"

    store.set_ref("P0700", to_raw(store.catalog.resolve("P0700").entry, 6))
    again = confirmed(client, "POST", url + "/commands/enable_operation", json={})
    assert again.status_code == 200 and again.json()["command_note"] is None


def test_the_faults_section_is_in_the_profile_schema(client: TestClient) -> None:
    schema = client.get("/api/profiles/schema").json()
    faults = schema["properties"]["faults"]
    assert "FaultsSection" in str(faults)
    entry = schema["$defs"]["FaultEntry"]
    assert {"number", "text", "source"} <= set(entry["required"]), "every fault entry names its source"


def test_faults_of_a_node_in_one_answer(client: TestClient) -> None:
    drive = _plant(client).nodes[MM]
    drive.drive.raise_fault(70, 0x7001)  # the simulated MICROMASTER trips: EMCY 0x7001 with F0070
    _newest_emcy(client, MM, "0x7001")
    faults = client.get(f"/api/sessions/{SESSION}/nodes/{MM}/faults").json()
    assert faults["present"]["fault"]["label"] == "F0070"
    assert [record["fault"]["label"] for record in faults["history"]][:1] == ["F0070"]
    assert faults["history"][0]["time"] > 0
    assert [p["ref"] for p in faults["parameters"]] == ["r0947", "r2110"]
    last_fault = faults["parameters"][0]
    assert last_fault["display"].startswith("70 = F0070") and last_fault["fault"]["label"] == "F0070", \
        "the simulated drive keeps its fault in r0947, read from the device and decoded"
    assert faults["command_note"].startswith("P0700 = 2 (Terminal)")
    assert "MICROMASTER 440 Parameter List" in faults["not_covered"]
    motec = client.get(f"/api/sessions/{SESSION}/nodes/{MOTEC}/faults").json()
    assert [p["ref"] for p in motec["parameters"]] == ["C00168"] and motec["command_note"] is None


def test_node_12_trip_in_the_monitor_and_the_node_list_names_its_error_number(client: TestClient) -> None:
    _plant(client).nodes[VECTOR].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
    _newest_emcy(client, VECTOR, "0x1000")
    nodes = client.get(f"/api/sessions/{SESSION}/nodes").json()
    vendor = next(n for n in nodes if n["node_id"] == VECTOR)["last_emcy"]["vendor_text"]
    assert vendor == "Lenze error number 16: Basic device in TRIP, message, warning, FAIL, QSP or persistent fault"
    rows: list[str] = []

    def traced() -> bool:
        rows[:] = [str(row) for row in client.get(f"/api/sessions/{SESSION}/monitor/trace?limit=10000").json()["rows"]]
        return any("Lenze error number 16" in row for row in rows)
    assert wait_until(traced, 10.0), "the monitor's EMCY row reads the error number from the vendor bytes"
