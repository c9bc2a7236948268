"""The Tools screen's planner against the demo plant's live bus, in a real browser.

A module of its own: the other Tools browser tests run a server on a temporary database (settings patched for
their module), and the session-wide demo server must never be started while that patch is in force.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.conftest import screenshot

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000


def test_type_a_node_id_then_scan_and_compare_at_once(page: Any, live_server: str) -> None:
    """Leaving a field re-checks the plan (the form's own request). A click on 'Scan and compare' right after typing
    must still scan: nothing in the button's row may move while that check runs (the 'scanning…' indicator once
    appeared for every check and pushed the button away between mouse down and up, so the click was lost)."""
    page.goto(f"{live_server}/tools")
    expect(page.locator("#findings .finding.none")).to_be_visible(timeout=WAIT_MS)
    page.locator('input[name="node_id_1"]').fill("5")
    page.locator("#planner-form button", has_text="Scan and compare").click()
    comparison = page.locator("#comparison")
    expect(comparison).to_be_visible(timeout=WAIT_MS)
    expect(comparison.locator('tr[data-node="5"]')).to_have_class("cmp-ok")
    expect(comparison.locator('tr[data-node="1"]')).to_have_class("cmp-missing")
    expect(comparison.locator('tr[data-node="3"]')).to_have_class("cmp-extra")
    comparison.scroll_into_view_if_needed()
    screenshot(page, "tools-planner-compare")
