"""The PDO tab in a real browser on the demo plant: node 3 (MICROMASTER 440) - edit RPDO5's mapping with the
picker, see the byte layout and the limits, apply, see the verified step report; a refused entry and the report
of the disabled PDO; a TPDO value changed in the simulator shown live; RPDO sends only after a confirmation;
cyclic sending ends when the page goes away."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from playwright.sync_api import expect

from drivebench.services.pdos.process_data import service as live_service
from drivebench.simulator.store import Abort
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app, wait_until


def test_edit_and_apply_rpdo5_of_the_micromaster(live_server: str, page: Any) -> None:
    page.goto(f"{live_server}/sessions/demo-plant/nodes/3?tab=pdo")
    card = page.locator("#pdo-rpdo5")
    card.wait_for(timeout=15000)
    assert "fixed" in page.locator("#pdo-rpdo1").inner_text().lower()
    card.locator("summary").click()
    search = card.locator(".pdo-search")
    search.fill("control word")
    card.get_by_role("button", name="Add 0x6040 Control word").click()
    search.fill("target torque")
    card.locator(".pdo-picker button").first.click()
    search.fill("0x2802")  # free object into drive (P2050.2): its name in the profile is the BICO one
    card.locator(".pdo-picker button").first.click()
    entries = card.locator(".pdo-entries li")
    entries.nth(2).drag_to(entries.nth(1))  # the MICROMASTER's mapping sequence: free object before the torque
    assert [entries.nth(i).locator(".mono").inner_text() for i in range(3)] == ["0x6040", "r2050.2", "0x6071"]
    trans_type = card.locator('input[name="transmission_type"]')
    trans_type.fill("3")
    assert "every 3. SYNC" in card.locator(".pdo-type-text").inner_text()
    assert "stores only synchronous/asynchronous" in card.locator(".pdo-type-text.warn-text").inner_text()
    trans_type.fill("255")
    assert card.locator(".pdo-type-text").inner_text() == "event-driven (device profile)"
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


def test_back_to_the_pdo_tab_gives_a_working_editor(live_server: str, page: Any) -> None:
    """Back from another tab restores htmx's snapshot of the page: its mapping editors are set up again."""
    from tests.web.test_ux_browser import Watch

    watch = Watch(page, live_server)
    page.goto(f"{live_server}/sessions/demo-plant/nodes/3?tab=pdo")
    page.locator("#pdo-rpdo5").wait_for(timeout=15000)
    page.click("nav.tabs a[data-tab=info]")
    page.locator("#node-tab[data-tab=info]").wait_for(timeout=15000)
    page.go_back()
    card = page.locator("#pdo-rpdo5")
    card.wait_for(timeout=15000)
    card.locator("summary").click()
    total = card.locator(".pdo-total")
    before = total.inner_text()
    entries = card.locator(".pdo-entries li")
    if entries.count():  # the shared server's RPDO5 may hold another test's mapping
        entries.first.locator("[data-act=remove]").click()
    else:
        card.locator(".pdo-search").fill("control word")
        card.get_by_role("button", name="Add 0x6040 Control word").click()
    assert total.inner_text() != before, "the editor did not react"
    screenshot(page, "pdo-editor-after-back")
    assert watch.problems == []


def test_motec_tab_shows_the_static_mapping_and_the_whole_c00593_text(live_server: str, page: Any) -> None:
    """8400 motec in its Lenze setting: each PDO lists its port's 4 words (count 0 = static mapping), and the
    response code C00593 is readable in full (it used to be cut off at the card's edge)."""
    page.goto(f"{live_server}/sessions/demo-plant/nodes/5?tab=pdo")
    card = page.locator("#pdo-rpdo1")
    card.wait_for(timeout=15000)
    assert "Nothing mapped" not in page.locator(".pdo-grid").inner_text()
    rows = card.locator(".pdo-signals tbody tr")
    assert rows.count() == 4
    assert [rows.nth(i).locator("td.mono").first.inner_text() for i in range(4)] == [
        "C00866/1", "C00866/2", "C00866/3", "C00866/4"]
    assert card.locator(".pdo-static-badge").is_visible()
    assert card.locator('.byte-layout[data-layout="current"] .byte-cell.free').count() == 0, "8 of 8 bytes used"
    response = card.locator("dd.pdo-setting").nth(2)
    assert "C00357/1 for the reception of the PDO CAN1_IN is exceeded" in response.inner_text()
    assert response.evaluate("el => el.scrollWidth <= el.clientWidth"), "C00593/1 text clipped"
    tpdo1 = page.locator("#pdo-tpdo1 .pdo-signals tbody tr")
    assert tpdo1.count() == 4 and "C00868/1" in tpdo1.first.inner_text()
    screenshot(page, "pdo-motec-static-1440")


@pytest.fixture(scope="module")
def own_server() -> Iterator[tuple[str, FastAPI]]:
    """A server of its own (the shared live server's plant is not reachable from a test): the tests below make the
    simulated drive refuse a mapping entry and change its values."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        yield base_url, app


def test_failed_apply_shows_the_step_and_the_disabled_pdo(own_server: tuple[str, FastAPI], page: Any) -> None:
    """The drive refuses the torque setpoint mid-sequence (a MICROMASTER 420 has no 6071)."""
    url, app = own_server
    store = app.state.drivebench.plants["demo-plant"].nodes[3].store

    def refuse_torque(index: int, sub: int, raw: object) -> None:
        if index == 0x1605 and raw == 0x60710010:
            raise Abort(0x06040041)

    store.add_write_check(refuse_torque)
    page.goto(f"{url}/sessions/demo-plant/nodes/3?tab=pdo")
    card = page.locator("#pdo-rpdo6")
    card.wait_for(timeout=15000)
    card.locator("summary").click()
    search = card.locator(".pdo-search")
    search.fill("control word")
    card.get_by_role("button", name="Add 0x6040 Control word").click()
    search.fill("target torque")
    card.locator(".pdo-picker button").first.click()
    card.get_by_role("button", name="Apply to device").click()
    report = page.locator("#pdo-rpdo6 .pdo-report.failed")
    report.wait_for(timeout=15000)
    text = report.inner_text()
    assert "Not applied" in text and "0x06040041" in text and "left disabled" in text
    assert "entry 2" in report.locator("li.failed").inner_text()
    assert "disabled" in page.locator("#pdo-rpdo6 .card-head .badge").first.inner_text()
    assert store.get(0x1405, 1) & 0x80000000
    screenshot(page, "pdo-apply-failed-mm4-rpdo6")


def test_live_value_confirmed_send_and_cyclic_stop(own_server: tuple[str, FastAPI], page: Any) -> None:
    url, app = own_server
    sim = app.state.drivebench.plants["demo-plant"].nodes[3]
    session = app.state.drivebench.manager.get("demo-plant")
    api = f"{url}/api/sessions/demo-plant/nodes/3/pdos"  # the mapping through the API; the browser uses it
    for pdo, entries in (("tpdo/5", [[0x6041, 0], [0x2803, 4]]), ("rpdo/5", [[0x6040, 0], [0x2802, 3]])):
        answer = httpx.put(f"{api}/{pdo}", json={"entries": entries}, timeout=20)
        assert answer.status_code == 200, answer.text
    page.goto(f"{url}/sessions/demo-plant/nodes/3?tab=pdo")
    page.locator("#pdo-rpdo5").wait_for(timeout=15000)
    page.locator("#pdo-ws-state.good").wait_for(timeout=15000)
    asked = page.locator("#moving-confirm")  # the server names what it will send; the page asks
    page.get_by_role("button", name="Start node").click()
    expect(asked).to_be_visible(timeout=15000)
    asked.get_by_role("button", name="Send it").click()
    assert wait_until(lambda: sim.state.name == "OPERATIONAL")
    assert "synchronous, acyclic" in page.locator("#pdo-tpdo5 .pdo-comm").inner_text()  # type 0: sent on SYNC
    sync = page.locator("#pdo-sync")
    sync.locator('input[name="period_ms"]').fill("50")
    sync.get_by_role("button", name="Start SYNC").click()
    page.locator("#pdo-sync .badge.good").wait_for(timeout=10000)
    assert "on, 50 ms" in sync.inner_text()
    sim.store.set(0x2803, 4, 4321)
    live = page.locator('#pdo-tpdo5 .live[data-ref="0x2803.4"]')
    assert wait_until(lambda: live.inner_text() == "4321"), live.inner_text()

    rpdo5 = page.locator("#pdo-rpdo5")
    rpdo5.locator('input[name="v:r2050.2"]').fill("77")
    rpdo5.get_by_role("button", name="Send once").click()
    expect(asked).to_be_visible(timeout=15000)
    expect(asked).to_contain_text("Sends to node 3")
    expect(asked.locator(".moving-confirm-values")).to_contain_text("r2050.2: 77")  # the value it will send
    asked.get_by_role("button", name="Cancel").click()
    assert sim.store.get(0x2802, 3) == 0, "nothing is sent without the confirmation"
    rpdo5.get_by_role("button", name="Send once").click()
    expect(asked).to_be_visible(timeout=15000)
    asked.get_by_role("button", name="Send it").click()
    assert wait_until(lambda: sim.store.get(0x2802, 3) == 77)
    # the frame can reach the drive before the page has swapped in the answer
    assert wait_until(lambda: "sent once" in rpdo5.locator(".send-result").inner_text())

    rpdo5.locator('input[name="v:r2050.2"]').fill("40000")  # INTEGER16: refused before anything is sent
    rpdo5.get_by_role("button", name="Send once").click()
    expect(asked).to_be_visible(timeout=15000)
    asked.get_by_role("button", name="Send it").click()
    error = rpdo5.locator(".send-result .error")
    error.wait_for(timeout=10000)
    assert "40000" in error.inner_text() and sim.store.get(0x2802, 3) == 77
    rpdo5.locator('input[name="v:r2050.2"]').fill("-300")
    rpdo5.get_by_role("button", name="Send cyclically").click()
    expect(asked).to_be_visible(timeout=15000)
    asked.get_by_role("button", name="Send it").click()
    assert wait_until(lambda: sim.store.get(0x2802, 3) == -300)
    assert wait_until(lambda: "sending every 100 ms" in rpdo5.locator(".send-result").inner_text())
    rpdo5.locator(".pdo-cyclic-badge").wait_for(state="visible", timeout=10000)  # from the socket's state message
    assert page.locator("#pdo-rpdo1 .pdo-cyclic-badge").is_hidden()
    screenshot(page, "pdo-live-mm4")
    assert live_service(session).cyclic
    page.close()  # the browser goes away: its cyclic RPDO stops
    assert wait_until(lambda: not live_service(session).cyclic)
    live_service(session).stop_sync()
