"""The Parameters tab in Chromium: a write that can move the drive is asked in the page's own dialog (in the
server's words, naming the node) before it is sent; cancelled, nothing goes out; confirmed, the tab's keep-alive
holds the node, and closing the tab quick-stops it. A control word that only stops the drive is not asked."""

from __future__ import annotations

from typing import Any

import pytest

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot, wait_until

pytestmark = pytest.mark.browser
expect = pytest.importorskip("playwright.sync_api").expect
WAIT_MS = 10_000
SEARCH_WAIT_MS = 30_000
"""The search answer: CI (4 workers and their Chromiums on 2 cores) once took over 10 s to show it."""
MM = 3


def _write(page: Any, ref: str, value: str) -> Any:
    if page.input_value("#param-q") != ref:
        page.fill("#param-q", ref)  # the search re-renders the rows: write in the row it shows
        expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=SEARCH_WAIT_MS)
    row = page.locator(f"tr[data-ref='{ref}']")
    row.locator("input[name=value]").fill(value)
    row.get_by_role("button", name="Write").click()
    return row


def test_the_parameters_tab_asks_before_a_write_that_moves_the_drive(demo_server: tuple[str, Plant],
                                                                     browser: Any) -> None:
    base, plant = demo_server
    sim = plant.nodes[MM]
    sim.store.set_ref("P0700", 6)  # commands from CAN (set at the drive)
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    page.goto(f"{base}/sessions/demo-plant/nodes/{MM}")
    dialog = page.locator("#moving-confirm")

    row = _write(page, "0x6040", "6")  # shutdown: cannot move it, sent without a question
    expect(row.locator("td.val")).to_contain_text("0x0006", timeout=WAIT_MS)
    assert not dialog.is_visible()
    assert page.locator("tr[data-ref='0x6040'] .badge.moves").count() == 1

    _write(page, "0x6040", "15")  # enable operation
    expect(dialog).to_be_visible(timeout=WAIT_MS)
    expect(page.locator("#moving-confirm .moving-confirm-text")).to_contain_text("Sends to node 3")
    expect(page.locator("#moving-confirm .moving-confirm-values")).to_contain_text("0x6040")  # what it will write
    screenshot(page, "parameters-moving-write-confirm")
    dialog.get_by_role("button", name="Cancel").click()
    expect(dialog).to_be_hidden()
    page.wait_for_timeout(300)
    assert sim.store.get(0x6040, 0) == 6, "cancelled: nothing was written"

    _write(page, "0x6040", "15")
    expect(dialog).to_be_visible(timeout=WAIT_MS)
    dialog.get_by_role("button", name="Send it").click()
    expect(page.locator("tr[data-ref='0x6040'] td.val")).to_contain_text("0x000F", timeout=WAIT_MS)
    assert sim.store.get(0x6040, 0) == 15
    expect(page.locator(".keepalive-state")).to_contain_text("keeps node 3 running", timeout=WAIT_MS)
    page.wait_for_timeout(3000)  # longer than the 2 s deadline: the open tab keeps it alive
    assert sim.store.get(0x6040, 0) == 15, "the open tab's keep-alive holds the node"
    context.close()  # the tab closes: quick stop
    assert wait_until(lambda: sim.store.get(0x6040, 0) & 0x06 == 0x02, 6), "no quick stop after the tab closed"
