"""The Parameters tab in Chromium on the demo plant (issue 30 item 5): node 5 (8400 motec) read, two settings
changed in their rows; "Changed from default" lists exactly those (and 0x1017, the heartbeat the plant file sets:
the simulator starts at the profile's factory values otherwise); undo of one write from the node's writes restores
it (read back, audit row ``undo <id>``); COB-IDs and identities show in hex, with a hex/decimal switch per row;
every row shows its factory value and range."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

pytestmark = pytest.mark.browser
expect = pytest.importorskip("playwright.sync_api").expect
WAIT_MS = 20_000
NODE = 5


def _search(page: Any, ref: str) -> Any:
    page.fill("#param-q", ref)
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=WAIT_MS)
    return page.locator(f"tr[data-ref='{ref}']")


def _write(page: Any, ref: str, value: str, shown: str) -> None:
    row = _search(page, ref)
    row.locator("input[name=value]").fill(value)
    row.get_by_role("button", name="Write").click()
    expect(page.locator(f"tr[data-ref='{ref}'] td.val")).to_contain_text(shown, timeout=WAIT_MS)
    expect(page.locator(f"tr[data-ref='{ref}'] .badge.verify")).to_contain_text("verified", timeout=WAIT_MS)


def _changed_refs(page: Any) -> set[str]:
    page.click("#changed-from-default")
    table = page.locator("#param-panel .changed-table")
    expect(table).to_be_visible(timeout=WAIT_MS)
    return set(table.locator("tbody tr").evaluate_all("rows => rows.map(r => r.dataset.ref)"))


def test_changed_from_default_undo_and_hex_on_node_5(app_db_url: str, demo_server: tuple[str, Plant],
                                                     browser: Any) -> None:
    base, plant = demo_server
    store = plant.nodes[NODE].store
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    page.goto(f"{base}/sessions/demo-plant/nodes/{NODE}")
    # The comparison reads every setting (the values the writes' audit rows name as old ones); a read-all would
    # switch SDO2 on (0x1201, not saved), which the comparison would rightly list.
    assert _changed_refs(page) == {"0x1017"}, "a fresh node 5 holds its factory values but the plant's heartbeat"
    page.click("#param-panel [data-close-panel]")
    expect(page.locator("#param-panel .changed-table")).to_have_count(0)

    row = _search(page, "C00088")  # the factory value and range beside the value
    expect(row.locator("td.def .factory")).to_have_text("10.20 A")
    cob = _search(page, "0x1800.1")
    value = cob.locator("td.val .v")
    cob_id = store.get(0x1800, 1)
    expect(value).to_have_text(f"0x{cob_id:08X}", timeout=WAIT_MS)
    cob.locator("button.radix").click()
    expect(value).to_have_text(str(cob_id))
    cob.locator("button.radix").click()
    expect(value).to_have_text(f"0x{cob_id:08X}")
    identity = _search(page, "0x1018.1")  # read-only: not a setting the comparison reads
    identity.get_by_role("button", name="Read").click()
    expect(page.locator("tr[data-ref='0x1018.1'] td.val .v")).to_have_text(f"0x{store.get(0x1018, 1):08X}",
                                                                            timeout=WAIT_MS)

    _write(page, "C00088", "12.5", "12.50 A")
    _write(page, "C00011", "1400", "1400 rpm")
    assert _changed_refs(page) == {"0x1017", "C00088", "C00011"}
    expect(page.locator("#param-panel tr[data-ref='C00088'] td.changed-value")).to_have_text("12.50 A")
    screenshot(page, "parameters-changed-from-default-1440")
    page.set_viewport_size({"width": 1024, "height": 800})
    screenshot(page, "parameters-changed-from-default-1024")
    assert page.evaluate("document.documentElement.scrollWidth <= window.innerWidth"), "no sideways scroll at 1024"
    page.set_viewport_size({"width": 1440, "height": 900})

    page.click("#node-writes-button")
    record = page.locator("#param-panel .writes-table tr[data-ref='C00088']").first  # not the comparison's row
    expect(record).to_be_visible(timeout=WAIT_MS)
    record_id = record.get_attribute("data-record")
    _search(page, "C00088")
    record.get_by_role("button", name="Undo").click()
    expect(page.locator("#param-panel .undo-result")).to_contain_text("verified", timeout=WAIT_MS)
    expect(page.locator("tr[data-ref='C00088'].prow td.val .v")).to_have_text("10.20 A", timeout=WAIT_MS)
    assert store.get_ref("C00088") == 1020
    screenshot(page, "parameters-undo-1440")
    newest = httpx.get(f"{base}/api/audit", params={"node_id": NODE}).json()[0]
    assert (newest["ref"], newest["origin"], newest["new_value"], newest["result"]) == (
        "C00088", f"undo {record_id}", "10.20 A", "written")
    expect(page.locator(f"#param-panel tr[data-record='{newest['id']}']")).to_contain_text("undo")
    assert _changed_refs(page) == {"0x1017", "C00011"}

    page.fill("#param-q", "TPDO")  # the communication parameters: COB-IDs in hex, factory values and ranges
    expect(page.locator("#param-rows tr[data-ref='0x1800.1'] td.def .factory")).to_have_text(
        f"0x{0x180 + NODE:08X}", timeout=WAIT_MS)
    for width in (1440, 1024):
        page.set_viewport_size({"width": width, "height": 900})
        screenshot(page, f"parameters-cob-ids-{width}")
        assert page.evaluate("document.documentElement.scrollWidth <= window.innerWidth"), f"sideways at {width}"
    page.fill("#param-q", "")  # every row, the longest names too: still no sideways scroll at 1024 px
    expect(page.locator("#param-rows")).not_to_have_attribute("data-count", "1", timeout=WAIT_MS)
    page.wait_for_timeout(500)
    assert page.evaluate("document.documentElement.scrollWidth <= window.innerWidth"), "sideways with all rows"
    context.close()
