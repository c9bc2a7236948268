"""The German UI in a real browser: the header's switch, German labels on the Plant page and a node's Parameters tab,
values and the monitor's load written as German writes numbers, and back to English.

Runs its own server on a Lenze plant (it writes a parameter; the shared live server stays untouched).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import Any

import pytest

from drivebench.web.app import create_app
from tests.conftest import fresh_channel, screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000
PLANT = {"name": "Linie 3", "nodes": [
    {"node_id": 5, "profile": "lenze-8400-motec-canopen", "name": "Förderband", "heartbeat_ms": 500},
]}
CLIPPED = """() => [...document.querySelectorAll("td, th, h1, button, nav a")]
  .filter((cell) => cell.scrollWidth > cell.clientWidth + 1).map((cell) => cell.textContent.trim().slice(0, 60))"""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    plant = tmp_path_factory.mktemp("plant") / "plant.json"
    plant.write_text(json.dumps(PLANT), encoding="utf-8")
    app = create_app(plant_file=plant, plant_bus=f"virtual:{fresh_channel()}@500000", latency="2ms")
    with serve_app(app) as base_url:
        yield base_url


def test_switch_to_german_and_back(server: str, page: Any) -> None:
    page.goto(server + "/")
    expect(page.locator("h1")).to_have_text("Plant")
    page.locator("#lang-de").click()

    expect(page.locator("h1")).to_have_text("Anlage", timeout=WAIT_MS)
    assert page.evaluate("document.documentElement.lang") == "de"
    nav = page.get_by_role("navigation", name="Ansichten")
    for label in ("Anlage", "Monitor", "Werkzeuge", "Parametersätze", "Profile", "Fernzugriff"):
        expect(nav.get_by_role("link", name=label, exact=True)).to_be_visible()
    card = page.locator("#session-linie-3")
    expect(card.get_by_role("button", name="Bus scannen")).to_be_visible()
    expect(card.get_by_role("button", name="NMT senden")).to_be_visible()
    expect(card.locator("table.nodes thead")).to_contain_text("NMT-Zustand")
    expect(page.locator("#node-linie-3-5 .nmt")).to_have_text("Pre-Operational", timeout=WAIT_MS)
    assert page.evaluate(CLIPPED) == []
    screenshot(page, "i18n-plant-de")

    page.locator("a[href='/sessions/linie-3/nodes/5']").first.click()
    expect(page.locator("h1")).to_contain_text("Knoten 5", timeout=WAIT_MS)
    expect(page.locator("nav.tabs a.active")).to_have_text("Parameter")
    expect(page.locator("#read-all")).to_have_text("Alle lesen")
    expect(page.locator("table.params thead")).to_contain_text("Neuer Wert")
    page.fill("#param-q", "rated motor current")  # vendor names stay as the manual prints them
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=WAIT_MS)
    row = page.locator("tr[data-ref='C00088']")
    row.locator("input[name=value]").fill("1234,5")  # a German decimal comma is understood
    row.get_by_role("button", name="Schreiben").click()
    value = page.locator("tr[data-ref='C00088'] td.val .v")
    expect(value).to_have_text("1.234,50 A", timeout=WAIT_MS)
    expect(page.locator("tr[data-ref='C00088'] td.val")).to_contain_text("geprüft")
    page.locator("tr[data-ref='C00088']").get_by_role("button", name="Lesen", exact=True).click()
    expect(value).to_have_text("1.234,50 A", timeout=WAIT_MS)
    expect(page.locator("tr[data-ref='C00088'] input[name=value]")).to_have_value("1234,5")  # as a German types it
    assert page.evaluate(CLIPPED) == []
    screenshot(page, "i18n-parameters-de")

    page.goto(server + "/monitor")  # the load figures are written by monitor.js, in the page's language
    expect(page.locator("#stat-load")).to_have_text(re.compile(r"^\d+,\d{1,2} %$"), timeout=WAIT_MS)
    expect(page.locator("#stat-since")).to_have_text(re.compile(r"^seit \d"))  # a text of monitor.js, in German

    page.locator("#lang-en").click()
    expect(page.locator("html")).to_have_attribute("lang", "en", timeout=WAIT_MS)
    page.goto(server + "/sessions/linie-3/nodes/5")
    expect(page.locator("nav.tabs a.active")).to_have_text("Parameters")
    expect(page.locator("#read-all")).to_have_text("Read all")


def test_the_language_switch_keeps_the_tab_chosen_since_the_page_loaded(server: str, page: Any) -> None:
    """The tabs change the address without loading the page (htmx): the switch goes back to the tab shown now."""
    page.goto(server + "/sessions/linie-3/nodes/5?tab=info")
    page.locator("nav.tabs a[data-tab=pdo]").click()
    expect(page).to_have_url(re.compile(r"\?tab=pdo$"), timeout=WAIT_MS)
    page.locator("#lang-de").click()
    expect(page.locator("html")).to_have_attribute("lang", "de", timeout=WAIT_MS)
    expect(page).to_have_url(re.compile(r"/sessions/linie-3/nodes/5\?tab=pdo$"))
    expect(page.locator("nav.tabs a.active")).to_have_attribute("data-tab", "pdo")
    page.locator("#lang-en").click()
    expect(page.locator("html")).to_have_attribute("lang", "en", timeout=WAIT_MS)
