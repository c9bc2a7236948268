"""Issue 27 item 1 in a real browser: on node 7's Control tab the jog dialog shows the speed the request sends (the
issue: it said 300 rpm and sent 2500), its confirm button is the hold-to-run button of exactly that jog, and a changed
speed is asked again (no confirmed-once flag)."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import expect

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot, wait_until

pytestmark = [pytest.mark.browser, pytest.mark.usefixtures("patient_guard")]

SERVO = 7
TIMEOUT_MS = 15_000


def _enable(page: Any, base: str) -> None:
    """Node 7's Control tab, the drive brought to operation enabled; the enable asked with the control word."""
    page.goto(f"{base}/sessions/demo-plant/nodes/{SERVO}?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    for command, state in (("shutdown", "ready"), ("switch_on", "switched_on")):
        page.click(f"button[data-command={command}]")
        page.wait_for_selector(f'.ctl-state.current[data-state="{state}"]', timeout=TIMEOUT_MS)
    page.click("button[data-command=enable_operation]")
    dialog = page.locator("#ctl-confirm")
    expect(dialog).to_be_visible(timeout=TIMEOUT_MS)
    expect(dialog.locator("#ctl-confirm-values")).to_contain_text("0x000F")  # the control word it writes
    page.click("#ctl-confirm-ok")
    page.wait_for_selector('.ctl-state.current[data-state="operation_enabled"]', timeout=TIMEOUT_MS)


def _jog_asks(page: Any, speed: str) -> Any:
    page.fill("#ctl-jog-speed", speed)
    page.click("button[data-jog='1']")
    dialog = page.locator("#ctl-confirm")
    expect(dialog).to_be_visible(timeout=TIMEOUT_MS)
    return dialog


def test_the_jog_dialog_shows_and_sends_the_speed_of_the_request(demo_server: tuple[str, Plant], page: Any) -> None:
    base, plant = demo_server
    sim = plant.nodes[SERVO]
    _enable(page, base)

    dialog = _jog_asks(page, "2500")
    values = dialog.locator("#ctl-confirm-values")
    expect(values).to_contain_text("2500 rpm")
    assert "300" not in values.inner_text().replace("2500", ""), values.inner_text()
    expect(dialog.locator("#ctl-confirm-text")).to_contain_text(f"node {SERVO}")
    hold = page.locator("#ctl-confirm-ok")
    expect(hold).to_contain_text("2500 rpm")
    screenshot(page, "control-jog-confirm-values")
    page.wait_for_timeout(300)
    assert sim.store.get(0x60FF, 0) == 0, "the press only asked: nothing moves before the confirmation"
    hold.hover()
    page.mouse.down()  # the dialog's button is the hold-to-run button: held, the jog runs at 2500 rpm
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 2500, TIMEOUT_MS / 1000), sim.store.get(0x60FF, 0)
    page.mouse.up()  # released: stops
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 0, TIMEOUT_MS / 1000)
    page.click("#ctl-confirm button[value=cancel]")
    expect(dialog).to_be_hidden()

    dialog = _jog_asks(page, "1000")  # another speed: asked again, showing it
    expect(dialog.locator("#ctl-confirm-values")).to_contain_text("1000 rpm")
    assert "2500" not in dialog.locator("#ctl-confirm-values").inner_text()
    page.locator("#ctl-confirm-ok").hover()
    page.mouse.down()
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 1000, TIMEOUT_MS / 1000), sim.store.get(0x60FF, 0)
    page.mouse.up()
    assert wait_until(lambda: sim.store.get(0x60FF, 0) == 0, TIMEOUT_MS / 1000)
    page.click("#ctl-confirm button[value=cancel]")
    page.click("button[data-command=quick_stop]")


def test_the_second_click_of_a_double_click_confirms_no_follow_up_question(
        demo_server: tuple[str, Plant], page: Any) -> None:
    """A velocity while the drive is enabled in another mode asks twice: the mode (0x6060), then the target (0x60FF).
    The second question opens in the same dialog milliseconds after the first closed, under the pointer: the second
    click of a double click on "Send it" must not answer a question nobody read."""
    base, plant = demo_server
    sim = plant.nodes[SERVO]
    _enable(page, base)
    dialog = page.locator("#ctl-confirm")

    page.fill("#ctl-velocity input[name=value]", "20")
    page.click("#ctl-velocity button[type=submit]")
    values = dialog.locator("#ctl-confirm-values")
    expect(values).to_contain_text("0x6060", timeout=TIMEOUT_MS)  # first the mode
    page.click("#ctl-confirm-ok")
    expect(values).to_contain_text("0x60FF", timeout=TIMEOUT_MS)  # then the target, in the same dialog
    expect(dialog).to_be_visible()
    page.locator("#ctl-confirm-ok").hover()
    page.mouse.down(click_count=2)  # the second click of a double click lands on the new question
    page.mouse.up(click_count=2)
    page.wait_for_timeout(300)
    expect(dialog).to_be_visible()
    expect(values).to_contain_text("0x60FF")
    assert sim.store.get(0x60FF, 0) == 0, "the follow-up question was answered by a double click"
    page.click("#ctl-confirm-ok")  # a click of its own answers it
    expect(dialog).to_be_hidden(timeout=TIMEOUT_MS)
    assert wait_until(lambda: sim.store.get(0x60FF, 0) != 0, TIMEOUT_MS / 1000), sim.store.get(0x60FF, 0)
    page.click("button[data-command=quick_stop]")
