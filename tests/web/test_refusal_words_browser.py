"""Why a drive refuses, in a real browser (issue 30 item 4): node 12 (8200 vector) trips on the demo plant, the
Control tab in German at 1024 px shows the present fault, and an enable clicked then says beside the buttons that
the fault holds the drive and which command acknowledges it; the page keeps no sideways scroll."""

from __future__ import annotations

from typing import Any
from urllib.parse import quote

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

TIMEOUT_MS = 20_000
VECTOR = 12


def test_enable_on_tripped_node_12_says_why_in_german_at_1024(demo_server: tuple[str, Plant], page: Any) -> None:
    base, plant = demo_server
    page.set_viewport_size({"width": 1024, "height": 800})
    page.goto(f"{base}/language/de?next={quote(f'/sessions/demo-plant/nodes/{VECTOR}?tab=control')}")
    page.wait_for_function("() => document.documentElement.lang === 'de'", timeout=TIMEOUT_MS)
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    note = page.locator("#ctl-command-note")
    assert note.is_hidden()
    plant.nodes[VECTOR].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
    page.wait_for_selector("#ctl-fault >> text=0x1000", timeout=TIMEOUT_MS)  # the status poll brings it

    page.click("button[data-command=enable_operation]")
    page.wait_for_function("() => document.querySelector('#ctl-confirm[open]') "
                           "|| !document.querySelector('#ctl-command-note').hidden", timeout=TIMEOUT_MS)
    if page.locator("#ctl-confirm[open]").count():
        page.click("#ctl-confirm-ok")
    note.wait_for(state="visible", timeout=TIMEOUT_MS)
    text = note.inner_text()
    assert "der Antrieb gibt nicht frei, solange ein Fehler ansteht" in text
    assert "Lenze error number 16" in text and "„Fehler quittieren“ senden" in text
    assert page.evaluate("document.documentElement.scrollWidth <= window.innerWidth"), "no sideways scroll at 1024"
    screenshot(page, "refusal-words-control-8200-de-1024")
