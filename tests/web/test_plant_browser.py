"""The Plant page in a real browser (Debian chromium) against the live server with the demo plant.

The live server is shared by the whole test session, so every test leaves the nodes pre-operational.
"""

from __future__ import annotations

import re
from typing import Any

from tests.conftest import screenshot

SESSION = "demo-plant"
DEMO_ROWS = {3: "Pump (MICROMASTER 440)", 5: "Conveyor (8400 motec)", 7: "Axis (generic CiA 402 servo)",
             12: "Fan (8200 vector + EMF2178IB)"}
TIMEOUT_MS = 10_000


def row(page: Any, node_id: int) -> Any:
    return page.locator(f"#node-{SESSION}-{node_id}")


def expect_states(page: Any, state: str) -> None:
    """Waits until every demo row shows ``state`` (the websocket pushes the table twice a second)."""
    from playwright.sync_api import expect

    for node_id in DEMO_ROWS:
        expect(row(page, node_id).locator(".nmt")).to_have_text(state, timeout=TIMEOUT_MS)


def send_nmt_to_all(page: Any, command: str) -> list[str]:
    """Choose the command, press Send NMT and accept the confirmation (and for start the page's question naming the
    values); returns the confirmation texts."""
    from playwright.sync_api import expect

    messages: list[str] = []

    def accept(dialog: Any) -> None:
        messages.append(dialog.message)
        dialog.accept()

    page.once("dialog", accept)
    card = page.locator(f"#session-{SESSION}")
    card.locator("select[name=command]").select_option(command)
    card.get_by_role("button", name="Send NMT").click()
    if command == "start":  # the server asks what it will send, and to which nodes: the page's dialog shows it
        asked = page.locator("#moving-confirm")
        expect(asked).to_be_visible(timeout=TIMEOUT_MS)
        messages.append(asked.inner_text())
        asked.get_by_role("button", name="Send it").click()
    return messages


def test_plant_page_shows_the_demo_nodes_live(live_server: str, page: Any) -> None:
    from playwright.sync_api import expect

    page.goto(live_server + "/")
    expect(page.locator("h1")).to_have_text("Plant")
    for node_id, device in DEMO_ROWS.items():
        expect(row(page, node_id).locator("td").nth(0)).to_have_text(str(node_id))
        expect(row(page, node_id).locator("td").nth(1)).to_contain_text(device)
    expect_states(page, "Pre-operational")
    ages = row(page, 5).locator("td").nth(3)
    expect(ages).to_have_text(re.compile(r"^\d+(\.\d)? (ms|s)$"), timeout=TIMEOUT_MS)
    first = ages.inner_text()
    expect(ages).not_to_have_text(first, timeout=TIMEOUT_MS)  # the age is live, not a page-load snapshot
    expect(row(page, 5).locator("td").nth(4)).to_have_text(re.compile(r"^\d+ ms$"))  # measured, about 500 ms
    screenshot(page, "plant-demo")


def test_nmt_start_all_then_pre_operational(live_server: str, page: Any) -> None:
    page.goto(live_server + "/")
    expect_states(page, "Pre-operational")
    confirmations = send_nmt_to_all(page, "start")
    expect_states(page, "Operational")
    assert confirmations and "ALL nodes" in confirmations[0]
    assert "every node of the session" in confirmations[1] and "NMT: start" in confirmations[1]
    screenshot(page, "plant-operational")
    send_nmt_to_all(page, "pre-operational")
    expect_states(page, "Pre-operational")


def test_refusing_the_confirmation_sends_nothing(live_server: str, page: Any) -> None:
    page.goto(live_server + "/")
    expect_states(page, "Pre-operational")
    page.once("dialog", lambda dialog: dialog.dismiss())
    card = page.locator(f"#session-{SESSION}")
    card.locator("select[name=command]").select_option("stop")
    card.get_by_role("button", name="Send NMT").click()
    page.wait_for_timeout(1500)
    expect_states(page, "Pre-operational")


def test_a_missing_adapter_is_reported_beside_the_form(live_server: str, page: Any) -> None:
    from playwright.sync_api import expect

    page.goto(live_server + "/")
    form = page.locator("#open-session")
    form.locator("select[name=interface]").select_option("pcan")
    form.locator("input[name=channel]").fill("PCAN_USBBUS1")
    form.get_by_role("button", name="Open session").click()
    error = page.locator("#open-session .error")
    expect(error).to_contain_text("pcan:PCAN_USBBUS1@500000", timeout=TIMEOUT_MS)
    expect(error).to_contain_text("PEAK driver")
    expect(page.locator("#open-session select[name=interface]")).to_have_value("pcan")  # the input is kept
    expect(page.locator("#open-session input[name=channel]")).to_have_value("PCAN_USBBUS1")
    assert "Traceback" not in page.content()
    screenshot(page, "plant-adapter-error")


def test_an_unknown_interface_name_is_reported_beside_the_form(live_server: str, page: Any) -> None:
    """The select offers only known names; a stale or hand-edited form can still send another one."""
    from playwright.sync_api import expect

    page.goto(live_server + "/")
    page.evaluate("""() => {
        const select = document.querySelector('#open-session select[name=interface]');
        select.add(new Option('socketcann', 'socketcann', true, true));
    }""")
    page.locator("#open-session input[name=channel]").fill("can0")
    page.locator("#open-session").get_by_role("button", name="Open session").click()
    error = page.locator("#open-session .error")
    expect(error).to_contain_text("Unknown CAN interface 'socketcann'", timeout=TIMEOUT_MS)
    expect(error.locator(".hint")).to_contain_text("socketcan")


def test_an_unreachable_gateway_is_reported_beside_the_form(live_server: str, page: Any) -> None:
    from playwright.sync_api import expect

    page.goto(live_server + "/")
    form = page.locator("#open-session")
    form.locator("select[name=interface]").select_option("socketcand")
    form.locator("input[name=channel]").fill("127.0.0.1:9/can0")
    form.get_by_role("button", name="Open session").click()
    error = page.locator("#open-session .error")
    expect(error).to_contain_text("127.0.0.1:9", timeout=TIMEOUT_MS)
    expect(error.locator(".hint")).to_contain_text("drivebench hub")
    screenshot(page, "plant-gateway-error")


def test_open_and_close_a_second_session_from_the_form(live_server: str, page: Any) -> None:
    from playwright.sync_api import expect

    page.goto(live_server + "/")
    form = page.locator("#open-session")
    form.locator("select[name=interface]").select_option("virtual")
    form.locator("input[name=channel]").fill("bench-2")
    form.locator("select[name=bitrate]").select_option("250000")
    form.locator("input[name=name]").fill("Bench 2")
    form.get_by_role("button", name="Open session").click()
    card = page.locator("#session-bench-2")
    expect(card.locator("h2")).to_have_text("Bench 2", timeout=TIMEOUT_MS)  # the page reloads with the new card
    expect(card).to_contain_text("virtual:bench-2@250000")
    expect(card.locator("table.nodes")).to_contain_text("No nodes yet")
    expect(row(page, 5)).to_be_visible()  # the demo plant is still there
    screenshot(page, "plant-two-sessions")
    page.once("dialog", lambda dialog: dialog.accept())
    card.get_by_role("button", name="Close").click()
    expect(card).to_have_count(0, timeout=TIMEOUT_MS)
    expect(row(page, 5)).to_be_visible()
