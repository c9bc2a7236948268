"""The PDO tab in a real browser on the demo plant: node 3 (MICROMASTER 440) - edit RPDO5's mapping with the
picker, see the byte layout and the limits, apply, see the verified step report."""

from __future__ import annotations

from typing import Any

from tests.conftest import screenshot


def test_edit_and_apply_rpdo5_of_the_micromaster(live_server: str, page: Any) -> None:
    page.goto(f"{live_server}/sessions/demo-plant/nodes/3?tab=pdo")
    card = page.locator("#pdo-rpdo5")
    card.wait_for(timeout=15000)
    assert "fixed" in page.locator("#pdo-rpdo1").inner_text().lower()
    card.locator("summary").click()
    search = card.locator(".pdo-search")
    search.fill("control word")
    card.get_by_role("button", name="Add 0x6040 Control word").click()
    search.fill("0x2802")  # free object into drive (P2050.2): its name in the profile is the BICO one
    card.locator(".pdo-picker button").first.click()
    search.fill("target torque")
    card.locator(".pdo-picker button").first.click()
    total = card.locator(".pdo-total")
    assert total.inner_text() == "6 / 8 bytes · 3 / 4 entries"
    assert card.locator('.byte-layout[data-layout="edit"] .byte-cell.free').count() == 2
    search.fill("0x6060")
    card.locator(".pdo-picker button").first.click()  # 7 bytes, 4 entries: the PDO is full
    search.fill("")
    assert card.get_by_role("button", name="Add 0x6042 vl target velocity").is_disabled()
    assert total.inner_text() == "7 / 8 bytes · 4 / 4 entries"
    screenshot(page, "pdo-editor-mm4-rpdo5")
    card.get_by_role("button", name="Apply to device").click()
    report = page.locator("#pdo-rpdo5 .pdo-report")
    report.wait_for(timeout=15000)
    assert "Applied and verified" in report.inner_text()
    assert "4 entries" in report.inner_text()
    assert page.locator("#pdo-rpdo5 .pdo-signals tbody tr").count() == 4
    screenshot(page, "pdo-applied-mm4-rpdo5")
