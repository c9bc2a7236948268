"""Safety interlocks in the browser: NMT start on the Plant page asks first (refusing sends nothing), the tab then
keeps the node alive and says so; closing the tab stops the drive (quick stop, NMT pre-operational). The node page
shows who holds a node's write lease to a second engineer."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi import FastAPI
from playwright.sync_api import expect

from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app, wait_until

MM, MOTEC = 3, 5
WAIT_MS = 10_000


@pytest.fixture
def own_server() -> Iterator[tuple[str, FastAPI]]:
    """A server of its own: the test reaches its simulated drives."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        yield base_url, app


def _plant(app: FastAPI) -> Plant:
    plant: Plant = app.state.drivebench.plants["demo-plant"]
    return plant


def test_nmt_start_asks_first_and_closing_the_tab_stops_the_drive(own_server: tuple[str, FastAPI],
                                                                  browser: Any) -> None:
    url, app = own_server
    sim = _plant(app).nodes[MM]
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    try:
        page.goto(url + "/")
        start = page.locator(f"#nmt-demo-plant-{MM}-start")
        asked = page.locator("#moving-confirm")  # the server names what it will send; the page asks
        start.click()
        expect(asked).to_be_visible(timeout=WAIT_MS)
        expect(asked).to_contain_text(f"Sends to node {MM}")
        expect(asked).to_contain_text("NMT: start")
        asked.get_by_role("button", name="Cancel").click()
        expect(asked).to_be_hidden(timeout=WAIT_MS)  # else the next click may find this answered dialog still shown
        time.sleep(0.5)
        assert sim.state.name == "PRE_OPERATIONAL", "refusing the confirmation sends nothing"

        start.click()
        expect(asked).to_be_visible(timeout=WAIT_MS)
        asked.get_by_role("button", name="Send it").click()
        assert wait_until(lambda: sim.state.name == "OPERATIONAL"), "NMT start did not reach the drive"
        note = page.locator("#session-demo-plant .keepalive-state")
        expect(note).to_have_text(f"This tab keeps node {MM} running: closing it stops it.", timeout=WAIT_MS)
        full = screenshot(page, "safety-plant-keepalive")
        page.screenshot(path=str(full.with_name("safety-plant-keepalive-top.png")))
        time.sleep(3)  # longer than the 2 s keep-alive timeout: the open tab keeps the node running
        assert sim.state.name == "OPERATIONAL"
    finally:
        context.close()  # closing the tab
    assert wait_until(lambda: sim.state.name == "PRE_OPERATIONAL"), "the node kept running after its tab closed"
    drive = sim.drive
    assert drive is not None and drive.control_word & 0x06 == 0x02, "no quick stop (0x6040 bit 1 set, bit 2 clear)"


def test_nmt_start_asks_even_when_the_node_table_is_redrawn_while_the_server_answers(
        own_server: tuple[str, FastAPI], browser: Any) -> None:
    """The websocket redraws the node table every few seconds: a redraw between the click and the server's 428 left
    the button detached, and the page never asked (nothing sent, nothing said). Here the redraw comes right after
    the request leaves, the same swap the socket makes."""
    url, app = own_server
    sim = _plant(app).nodes[MM]
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    try:
        page.goto(url + "/")
        start = page.locator(f"#nmt-demo-plant-{MM}-start")
        expect(start).to_be_visible(timeout=WAIT_MS)
        page.evaluate("""(id) => {
            window.redrawn = 0;
            document.body.addEventListener("htmx:beforeRequest", (event) => {
                if (event.detail.elt.id !== id || window.redrawn) return;
                const table = document.getElementById("nodes-demo-plant");
                htmx.swap(table, table.outerHTML, {swapStyle: "outerHTML"});
                window.redrawn += 1;
            });
        }""", f"nmt-demo-plant-{MM}-start")
        start.click()
        asked = page.locator("#moving-confirm")
        expect(asked).to_be_visible(timeout=WAIT_MS)
        assert page.evaluate("window.redrawn") == 1, "the table was not redrawn during the request"
        expect(asked).to_contain_text(f"Sends to node {MM}")
        asked.get_by_role("button", name="Send it").click()
        assert wait_until(lambda: sim.state.name == "OPERATIONAL"), "NMT start did not reach the drive"
    finally:
        context.close()
    assert wait_until(lambda: sim.state.name == "PRE_OPERATIONAL"), "the node kept running after its tab closed"


def test_a_slow_press_on_nmt_start_is_not_lost_to_the_table_redraw(own_server: tuple[str, FastAPI],
                                                                    browser: Any) -> None:
    """The node table comes over the websocket twice a second; a press held across a redraw used to lose the click
    (the release landed on a new button, the click on the table: no dialog, nothing sent)."""
    url, _app = own_server
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    try:
        page.goto(url + "/")
        start = page.locator(f"#nmt-demo-plant-{MM}-start")
        expect(start).to_be_visible(timeout=WAIT_MS)
        page.wait_for_function("document.querySelector('#nodes-demo-plant') !== null")
        box = None
        deadline = time.monotonic() + WAIT_MS / 1000
        while box is None and time.monotonic() < deadline:  # none while a redraw swaps the table (twice a second)
            box = start.bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.down()
        time.sleep(2.0)  # four pushes of the table
        page.mouse.up()
        expect(page.locator("#moving-confirm")).to_be_visible(timeout=WAIT_MS)
        page.locator("#moving-confirm").get_by_role("button", name="Cancel").click()
    finally:
        context.close()


def test_second_engineer_sees_the_lease_holder_on_the_node_page(own_server: tuple[str, FastAPI],
                                                                browser: Any) -> None:
    url, _app = own_server
    context = browser.new_context(viewport={"width": 1440, "height": 900}, extra_http_headers={
        "X-DriveBench-User": "ben"})
    page = context.new_page()
    try:
        anna = page.request.put(f"{url}/api/sessions/demo-plant/nodes/{MOTEC}/parameters/C00039/1",
                                data={"value": 12.5, "verify": False},
                                headers={"X-DriveBench-User": "anna", "X-DriveBench-Client": "anna-tab"})
        assert anna.ok, anna.text()
        page.goto(f"{url}/sessions/demo-plant/nodes/{MOTEC}")
        banner = page.locator("#lease-slot .held-by-other")
        expect(banner).to_contain_text(f"Node {MOTEC} is being written by anna (since ", timeout=WAIT_MS)
        expect(banner).to_contain_text("writes are refused until anna finishes or the lease expires in")
        expect(banner.locator("button", has_text="Break lease")).to_be_visible()
        page.screenshot(path=str(screenshot(page, "safety-lease-banner").with_name("safety-lease-banner-top.png")))
        page.once("dialog", lambda dialog: dialog.accept())
        banner.locator("button", has_text="Break lease").click()
        note = page.locator("#lease-note")
        expect(note).to_contain_text("Lease of anna broken (logged).", timeout=WAIT_MS)
        page.wait_for_timeout(4000)  # longer than the lease slot's 3 s refresh: the answer is not wiped by it
        expect(note).to_contain_text("Lease of anna broken (logged).")
        expect(page.locator("#lease-slot .held-by-other")).to_have_count(0)
    finally:
        context.close()
