"""The Control tab of the demo plant's generic CiA 402 servo (node 7, software position limits 0x607D ±3600 °) in a
real browser: a held jog forward ends at +3600 ° where the drive clamps, the tab lights "Internal limit active
(0x6041 bit 11)" and says the drive clamped; with the drive's own clamping off (0x2100 = 0, set at the drive) a
held jog reverse is halted by DriveBench before -3600 ° and the tab says so."""

from __future__ import annotations

from typing import Any

import pytest

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

pytestmark = pytest.mark.browser

TIMEOUT_MS = 30_000
AXIS = 7


def _current(page: Any, state: str) -> None:
    page.wait_for_selector(f'.ctl-state.current[data-state="{state}"]', timeout=TIMEOUT_MS)


def _hold(page: Any, direction: int) -> None:
    """Press a jog button: the dialog names the jog, and its confirm button is the hold-to-run button of exactly that
    jog; hold it."""
    page.click(f"button[data-jog='{direction}']")
    hold = page.locator("#ctl-confirm-ok")
    hold.wait_for(state="visible", timeout=TIMEOUT_MS)
    hold.hover()
    page.mouse.down()


def test_the_control_tab_shows_the_internal_limit_bit_and_who_stopped_the_jog(demo_server: tuple[str, Plant],
                                                                               page: Any) -> None:
    base, plant = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/{AXIS}?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    _current(page, "switch_on_disabled")
    assert page.locator("#ctl-limit").is_hidden() and page.locator("#ctl-limit-note").is_hidden()
    page.click("button[data-command=shutdown]")
    _current(page, "ready")
    page.click("button[data-command=switch_on]")
    _current(page, "switched_on")
    page.click("button[data-command=enable_operation]")
    page.click("#ctl-confirm-ok")
    _current(page, "operation_enabled")

    _hold(page, 1)
    page.wait_for_selector("#ctl-limit-note:not([hidden])", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-limit-note").inner_text() == (
        "Stopped at the software limit +3600 °: the drive clamped (0x6041 bit 11 internal limit active).")
    assert page.locator("#ctl-limit").inner_text() == "Internal limit active (0x6041 bit 11)"
    assert page.locator("#ctl-limit").is_visible()
    assert page.locator('#ctl-sw-bits tr[data-bit="11"]').get_attribute("class") == "on"
    screenshot(page, "control-software-limit-clamped")
    page.mouse.up()  # released: setpoint 0, the limit no longer holds a motion
    page.wait_for_selector("#ctl-limit", state="hidden", timeout=TIMEOUT_MS)
    page.click("#ctl-confirm button[value=cancel]")

    plant.nodes[AXIS].store.set(0x2100, 0, 0)  # at the drive: it no longer keeps to 0x607D itself
    _hold(page, -1)
    page.wait_for_function("() => (document.querySelector('#ctl-limit-note').textContent || '')"
                           ".startsWith('DriveBench halted the jog')", timeout=TIMEOUT_MS)
    note = page.locator("#ctl-limit-note").inner_text()
    assert "before the software limit -3600 ° (0x607D; the drive does not clamp there itself)" in note, note
    assert page.locator("#ctl-limit").is_hidden()  # the drive did not limit anything
    screenshot(page, "control-software-limit-halted")
    page.mouse.up()
    page.click("#ctl-confirm button[value=cancel]")
    page.click("button[data-command=quick_stop]")
