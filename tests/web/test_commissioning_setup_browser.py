"""Issue 30 items 3 and 5 in a real browser, in German at 1024 px: node 7's Control tab offers the generic CiA 402
set-up as a guided form (the modes the drive supports, the objects its profile lacks, the present value), a step
written with the user's value and read back; then the Sets page's audit log undoes that write, read back."""

from __future__ import annotations

from typing import Any

import pytest

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot
from tests.web.test_quick_commissioning_browser import _fill, _form_ref, _next

pytestmark = pytest.mark.browser
expect = pytest.importorskip("playwright.sync_api").expect
TIMEOUT_MS = 20_000
CLIPPED = """(root) => [...document.querySelectorAll(root + " td, " + root + " th, " + root + " button, "
  + root + " label, " + root + " li")].filter((cell) => cell.offsetParent && cell.scrollWidth > cell.clientWidth + 1)
  .map((cell) => cell.textContent.trim().slice(0, 60))"""
SIDEWAYS = "document.documentElement.scrollWidth > window.innerWidth"


def test_cia402_set_up_in_german_and_its_undo_on_the_sets_page(app_db_url: str, demo_server: tuple[str, Plant],
                                                                browser: Any) -> None:
    base, plant = demo_server
    store = plant.nodes[7].store
    context = browser.new_context(viewport={"width": 1024, "height": 800})
    page = context.new_page()
    page.goto(f"{base}/language/de?next=/")  # the header's switch (folded into its menu at 1024 px)
    expect(page.locator("h1")).to_have_text("Anlage", timeout=TIMEOUT_MS)

    page.goto(f"{base}/sessions/demo-plant/nodes/7?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    page.select_option("#ctl-seq", "cia402-setup")
    page.click("#ctl-seq-start")
    page.wait_for_selector("#ctl-step-form[data-ref='0x6060']", timeout=TIMEOUT_MS)
    run = page.locator("#ctl-run")
    expect(run).to_contain_text("CiA-402-Einrichtung")
    expect(run.locator(".ctl-missing")).to_contain_text("0x6080")  # the servo's profile has no max motor speed
    expect(run).to_contain_text("Betriebsarten, die dieser Antrieb unterstützt")
    page.wait_for_function("() => document.querySelector('#ctl-step-present').textContent !== '…'",
                           timeout=TIMEOUT_MS)
    while _form_ref(page) != "0x6083":
        _next(page)  # the proposals: the profile's defaults (0x6060 asks for the confirmation)
    _fill(page, "0x6083", "5000")
    _next(page)
    assert store.get(0x6083, 0) == 5000
    assert page.locator("table.ctl-run tr.failed").count() == 0
    assert page.evaluate(CLIPPED, "#ctl-run") == [] and not page.evaluate(SIDEWAYS)
    screenshot(page, "commissioning-cia402-setup-de-1024")

    page.goto(f"{base}/parameter-sets#audit")
    record = page.locator("#audit-block tr", has_text="0x6083").first
    expect(record).to_be_visible(timeout=TIMEOUT_MS)
    record.get_by_role("button", name="Rückgängig").click()
    expect(page.locator("#audit-block .undo-result")).to_contain_text("geprüft", timeout=TIMEOUT_MS)
    assert store.get(0x6083, 0) == 3000  # the old value, read back
    assert page.evaluate(CLIPPED, "#audit-block") == [] and not page.evaluate(SIDEWAYS)
    screenshot(page, "sets-audit-undo-de-1024")
    context.close()
