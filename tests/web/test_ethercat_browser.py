"""The issue's "done when" in a real browser, on a server of its own with the demo plant (as `make run` starts it):
the Plant page shows the EtherCAT line with station addresses and EtherCAT states; C00039/1 of the simulated
8400 motec EtherCAT unit reads 40.00 % (0x0FA0) and a write is verified; a parameter set round trip (upload,
preview, download, roll back); and after switching the unit to Safe-Operational a PDO mapping write is refused with
the manual's words."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from tests.conftest import screenshot
from tests.web.test_parameter_sets_browser import sets_server  # noqa: F401 - the demo plant with its own database
from tests.web.test_parameters_browser import _row, _search

expect = pytest.importorskip("playwright.sync_api").expect
pytestmark = pytest.mark.browser

WAIT_MS = 20_000
SESSION = "ethercat-line"


def test_ethercat_unit_in_the_browser(sets_server: str, page: Any) -> None:  # noqa: F811 - the fixture
    server = sets_server
    page.goto(server + "/")
    card = page.locator(f"#session-{SESSION}")
    expect(card.locator("h2")).to_have_text("EtherCAT line")
    first = page.locator(f"#node-{SESSION}-1")
    expect(first.locator("td.station")).to_have_text("1001")
    expect(first.locator(".esm")).to_have_text("Pre-Operational")
    expect(page.locator(f"#node-{SESSION}-2 td.station")).to_have_text("1002")
    card.scroll_into_view_if_needed()
    screenshot(page, "ethercat-plant")

    # C00039/1 reads 40.00 % (0x0FA0 raw), a write is verified
    page.locator(f"#link-{SESSION}-1").click()
    expect(page.locator("h1")).to_contain_text("Slave 1 (station 1001)", timeout=WAIT_MS)
    _search(page, "C00039/1")
    _row(page, "C00039/1").get_by_role("button", name="Read").click()
    expect(_row(page, "C00039/1").locator("td.val")).to_contain_text("40.00 %", timeout=WAIT_MS)
    _row(page, "C00039/1").locator("input[name=value]").fill("55")
    _row(page, "C00039/1").get_by_role("button", name="Write").click()
    expect(_row(page, "C00039/1").locator("td.val")).to_contain_text("55.00 %", timeout=WAIT_MS)
    expect(_row(page, "C00039/1").locator("td.val")).to_contain_text("verified")
    screenshot(page, "ethercat-parameter-written")

    # parameter set round trip: the unit as found (55 %) stored, changed back to 40 %, the set downloaded, rolled back
    page.goto(f"{server}/parameter-sets")
    upload = page.locator("#upload-card form")
    upload.locator("select[name=target]").select_option(f"{SESSION}:1")
    upload.locator("input[name=name]").fill("Palletiser at 55 %")
    upload.get_by_role("button", name="Upload all parameters").click()
    expect(page.locator("#upload-result .ok")).to_contain_text("Stored as set", timeout=WAIT_MS)
    written = httpx.put(f"{server}/api/sessions/{SESSION}/nodes/1/parameters/C00039/1", json={"value": 40},
                        timeout=10)
    assert written.status_code == 200, written.text
    page.reload()
    page.locator("#set-list a", has_text="Palletiser at 55 %").click()
    expect(page.locator("#set-detail h2")).to_have_text("Palletiser at 55 %", timeout=WAIT_MS)
    page.locator("#set-detail").get_by_role("button", name="Preview changes").click()
    preview = page.locator("#download-area .preview")
    expect(preview.locator("tbody tr")).to_have_count(1, timeout=WAIT_MS)
    expect(preview).to_contain_text("40.00 %")
    expect(preview).to_contain_text("55.00 %")
    preview.get_by_role("button", name="Download 1 changes").click()
    # the set holds a command source, which the unit holds already: only C00039/1 is written, nothing to confirm
    report = page.locator("#download-area .report")
    expect(report).to_have_attribute("data-state", "done", timeout=WAIT_MS)
    expect(report.locator(".report-table")).to_contain_text("written")
    screenshot(page, "ethercat-set-downloaded")
    page.once("dialog", lambda dialog: dialog.accept())
    report.get_by_role("button", name="Roll back").click()
    rolled = page.locator("#download-area .report")
    expect(rolled).to_contain_text("Rollback", timeout=WAIT_MS)
    expect(rolled).to_have_attribute("data-state", "done", timeout=WAIT_MS)
    expect(rolled.locator(".report-table")).to_contain_text("40.00 %")

    # Safe-Operational: a PDO mapping write is refused with the manual's words
    page.goto(server + "/")
    page.locator(f"#nmt-{SESSION}-1-stop").click()
    expect(page.locator(f"#node-{SESSION}-1 .esm")).to_have_text("Safe-Operational", timeout=WAIT_MS)
    screenshot(page, "ethercat-safe-operational")
    page.locator(f"#link-{SESSION}-1").click()
    expect(page.locator("h1")).to_contain_text("Slave 1 (station 1001)", timeout=WAIT_MS)
    page.fill("#param-q", "0x1A00.1")  # finds 0x1A00.1 and 0x1A00.10; the search answer replaces the rows
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "2", timeout=WAIT_MS)
    _row(page, "0x1A00.1").locator("input[name=value]").fill(str(0x5C930110))
    _row(page, "0x1A00.1").get_by_role("button", name="Write").click()
    error = _row(page, "0x1A00.1").locator("td.edit .error")
    expect(error).to_contain_text("Due to the current device state, data cannot be transferred to the application "
                                  "or stored in the application", timeout=WAIT_MS)
    expect(error).to_contain_text("0x08000022")
    screenshot(page, "ethercat-mapping-refused")

    # Info tab: the object list through the CoE SDO information service, against the profile
    page.goto(f"{server}/sessions/{SESSION}/nodes/1?tab=info")
    page.get_by_role("button", name="Read object list from device").click()
    listed = page.locator("#object-list")
    expect(listed).to_contain_text("The device reports 36 objects, the profile lists 36; 36 in both.",
                                   timeout=WAIT_MS)
    # PDO tab: the EtherCAT rules of the profile, not the CANopen unit's
    page.goto(f"{server}/sessions/{SESSION}/nodes/1?tab=pdo")
    expect(page.locator(".pdo-notes")).to_contain_text("0x1C12", timeout=WAIT_MS)
    expect(page.locator(".pdo-notes")).not_to_contain_text("CAN1_IN")
    # ... the assignment read from the slave and its mapping editor: still Safe-Operational, the write is refused
    expect(page.locator("#ecat-assign-tpdo")).to_contain_text("0x1A00", timeout=WAIT_MS)
    rx = page.locator("#ecat-pdo-rpdo1")
    rx.locator("input[name=entries]").fill("0x5C93.1")  # the manual's example: C00876/1
    rx.get_by_role("button", name="Write mapping").click()
    refused = page.locator("#ecat-pdo-rpdo1 .pdo-report.failed")
    expect(refused).to_contain_text("0x08000022", timeout=WAIT_MS)
    expect(refused).to_contain_text("Take the slave to Pre-Operational on the Plant page first")
    screenshot(page, "ethercat-pdo-mapping-refused")
    # Parameters tab: SDOs go through the slave's CoE mailbox
    page.goto(f"{server}/sessions/{SESSION}/nodes/1?tab=parameters")
    expect(page.locator("#sdo-settings summary")).to_contain_text("CoE mailbox (station 1001, gateway ethercat-mbg:")
    screenshot(page, "ethercat-sdo-label")
