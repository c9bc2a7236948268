"""Node 12's trip where the profile has no text for its number, in real browsers in German at 1024 px (issue 30
item 4): the Diagnostics tab shows the present fault and what the profile's sources did not give, and a share link
opened in a second browser shows the same fault and note, read-only; neither page scrolls sideways."""

from __future__ import annotations

from typing import Any
from urllib.parse import quote

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

TIMEOUT_MS = 20_000
VECTOR = 12
NARROW = {"width": 1024, "height": 800}
NO_SIDEWAYS_SCROLL = "document.documentElement.scrollWidth <= window.innerWidth"


def _german(page: Any, base: str, path: str) -> None:
    page.goto(f"{base}/language/de?next={quote(path)}")
    page.wait_for_function("() => document.documentElement.lang === 'de'", timeout=TIMEOUT_MS)


def test_node_12_trip_on_diagnostics_and_through_a_share_link_in_german_at_1024(
        demo_server: tuple[str, Plant], browser: Any) -> None:
    base, plant = demo_server
    engineer = browser.new_context(viewport=NARROW)
    remote = browser.new_context(viewport=NARROW, locale="de-DE")  # the link holder's browser asks for German
    try:
        page = engineer.new_page()
        _german(page, base, "/remote")
        page.click("form button[type=submit]")  # default shows: health + faults
        url = page.locator("input.share-url").input_value()

        plant.nodes[VECTOR].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
        _german(page, base, f"/sessions/demo-plant/nodes/{VECTOR}?tab=diagnostics")
        page.wait_for_selector("#diag-present-fault >> text=Lenze error number 16", timeout=TIMEOUT_MS)
        assert "8200 vector system manual" in page.locator("#diag-faults-not-covered").inner_text()
        assert page.evaluate(NO_SIDEWAYS_SCROLL), "Diagnostics: no sideways scroll at 1024"
        screenshot(page, "fault-gaps-diagnostics-8200-de-1024")

        viewer = remote.new_page()
        viewer.goto(url)
        assert viewer.evaluate("document.documentElement.lang") == "de"
        node = viewer.locator(".remote-node[data-node='12']")
        node.locator(".remote-present-fault >> text=Lenze error number 16").wait_for(timeout=TIMEOUT_MS)
        assert "keinen Text" in node.locator(".remote-present-fault").inner_text(), "says the profile has no text"
        assert "8200 vector system manual" in node.locator(".remote-not-covered").inner_text()
        assert viewer.locator("button").count() == 0, "the remote view offers no action"
        assert viewer.evaluate(NO_SIDEWAYS_SCROLL), "share link: no sideways scroll at 1024"
        screenshot(viewer, "fault-gaps-share-link-8200-de-1024")
    finally:
        remote.close()
        engineer.close()
