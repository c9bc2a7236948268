"""Why a drive refuses (issue 30 item 4) over the real API on the demo plant: a simulated drive trips (its EMCY on
the virtual bus, its state machine in fault), and an enable sent then answers what holds the drive: the fault state,
the present fault in the manual's words where the profile has them, and the command that acknowledges it."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant
from tests.confirming import confirmed
from tests.conftest import wait_until

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

SESSION = "demo-plant"
MM, VECTOR = 3, 12
F0070 = 0x7001  # EMCY code of MICROMASTER fault F0070 (CANopen option module manual, Table 3-14)


def _plant(client: TestClient) -> Plant:
    plants: dict[str, Plant] = client.app.state.drivebench.plants  # type: ignore[attr-defined]
    return plants[SESSION]


def _tripped(client: TestClient, node: int) -> str:
    url = f"/api/sessions/{SESSION}/nodes/{node}/control"
    assert wait_until(lambda: (status := client.get(url).json())["fault"] and status["present_fault"], 10.0), \
        f"node {node} did not report its trip"
    return url


def test_enable_on_a_tripped_8200_vector_says_the_fault_holds_it_and_how_to_reset(client: TestClient) -> None:
    url = f"/api/sessions/{SESSION}/nodes/{VECTOR}/control"
    calm = confirmed(client, "POST", url + "/commands/enable_operation", json={})
    assert calm.status_code == 200 and calm.json()["command_note"] is None, "no fault, nothing to explain"
    _plant(client).nodes[VECTOR].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
    _tripped(client, VECTOR)

    refused = confirmed(client, "POST", url + "/commands/enable_operation", json={})
    assert refused.status_code == 200, refused.text
    status = refused.json()
    assert status["state"] == "fault", "the simulated 8200 vector stays in TRIP"
    note = status["command_note"]
    assert note is not None and note.startswith("Fault active: the drive does not enable while a fault is present")
    assert "Lenze error number 16, EMCY 0x1000: Basic device in TRIP" in note, "the number and the EMCY's words"
    assert note.endswith("Remove its cause, then send “Fault reset”."), "the control's own reset command"


def test_enable_on_a_tripped_micromaster_names_the_fault_and_the_command_source(client: TestClient) -> None:
    url = f"/api/sessions/{SESSION}/nodes/{MM}/control"
    _plant(client).nodes[MM].drive.raise_fault(70, F0070)
    _tripped(client, MM)
    note = confirmed(client, "POST", url + "/commands/enable_operation", json={}).json()["command_note"]
    assert "(F0070: Control board setpoint timeout" in note, "the manual's text for the device's own number"
    assert "P0700 = 2 (Terminal)" in note, "the command-source note still follows"

    reset = confirmed(client, "POST", url + "/commands/fault_reset", json={}).json()["command_note"]
    assert reset is None or "does not enable" not in reset, "the reset's own effect shows in the next status"
