"""Faults in the manual's words in a real browser (issue 30 item 4): a simulated drive trips on the demo plant, the
Control and Diagnostics tabs show the present fault with the device's own fault number, the manual's text and
remedy and where they come from; node 12's trip shows its Lenze error number and says the profile has no text for
it (the 8200 vector's fault table is not in the sources)."""

from __future__ import annotations

from typing import Any

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

TIMEOUT_MS = 20_000
F0070 = 0x7001  # EMCY code of MICROMASTER fault F0070 (CANopen option module manual, Table 3-14)


def test_micromaster_trip_shows_fault_text_and_remedy_on_control_and_diagnostics(
        demo_server: tuple[str, Plant], page: Any) -> None:
    base, plant = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=control")
    page.wait_for_selector("#ctl-state-label", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-fault").is_hidden()
    plant.nodes[3].drive.raise_fault(70, F0070)  # the simulated drive trips: fault reaction, EMCY 0x7001 + F0070
    fault = page.locator("#ctl-fault")
    fault.wait_for(state="visible", timeout=TIMEOUT_MS)  # the status poll brings it, no reload
    page.wait_for_selector("#ctl-fault >> text=F0070", timeout=TIMEOUT_MS)
    text = fault.inner_text()
    assert "Control board setpoint timeout" in text and "P2040" in text
    assert "Remedy: Check whether the CANopen master has stopped" in text
    assert "Issue 01/05" in text, "the entry names its source"
    screenshot(page, "fault-words-control-mm4")

    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=diagnostics")
    page.wait_for_selector("#diag-present-fault >> text=F0070", timeout=TIMEOUT_MS)
    present = page.locator("#diag-present-fault").inner_text()
    assert "Remedy: Check whether the CANopen master has stopped" in present
    row = page.locator("#diag-emcy tbody tr").first
    assert "F0070" in row.inner_text() and "Remedy:" in row.inner_text()
    screenshot(page, "fault-words-diagnostics-mm4")


def test_node_12_trip_shows_its_error_number_and_what_the_profile_lacks(
        demo_server: tuple[str, Plant], page: Any) -> None:
    base, plant = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/12?tab=control")
    page.wait_for_selector("#ctl-state-label", timeout=TIMEOUT_MS)
    plant.nodes[12].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
    page.wait_for_selector("#ctl-fault >> text=0x1000", timeout=TIMEOUT_MS)
    text = page.locator("#ctl-fault").inner_text()
    assert "Basic device in TRIP" in text and "16" in text
    assert "this fault number has no text in the device profile" in text
    screenshot(page, "fault-words-control-8200")
    page.goto(f"{base}/sessions/demo-plant/nodes/12?tab=diagnostics")
    page.wait_for_selector("#diag-present-fault >> text=0x1000", timeout=TIMEOUT_MS)
    assert "no text in the device profile" in page.locator("#diag-present-fault").inner_text()
    screenshot(page, "fault-words-diagnostics-8200")


def test_diagnostics_reads_the_fault_parameters_and_says_why_commands_do_nothing(
        demo_server: tuple[str, Plant], page: Any) -> None:
    base, _ = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=diagnostics")
    page.wait_for_selector("#diag-faults >> text=r0947", timeout=TIMEOUT_MS)
    assert "P0700 = 2 (Terminal)" in page.locator("#diag-command-note").inner_text()
    assert "MICROMASTER 440 Parameter List" in page.locator("#diag-faults-not-covered").inner_text()
    screenshot(page, "fault-words-parameters-mm4")
