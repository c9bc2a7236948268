"""The MICROMASTER's quick commissioning in a real browser on the demo plant (issue 30, "done when"): the guided
form from P0010 = 1 to P3900 with each parameter's unit, range and present value; P1120 = 9999 refused with its
range; a reload shows where the run stands; at the end the motor turns when enabled over CANopen."""

from __future__ import annotations

from typing import Any

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot

TIMEOUT_MS = 15_000
NAMEPLATE = {"P0100": "0", "P0300": "1", "P0304": "400", "P0305": "1.9", "P0307": "0.75", "P0308": "0.82",
             "P0309": "78", "P0310": "50", "P0311": "1395", "P1120": "2"}
ANSWERED = "document.querySelectorAll('table.ctl-run tr.done').length > {done}"


def _form_ref(page: Any) -> str | None:
    form = page.locator("#ctl-step-form")
    return str(form.get_attribute("data-ref")) if form.count() else None


def _fill(page: Any, ref: str, value: str) -> None:
    field = page.locator("#ctl-step-value")
    if field.evaluate("el => el.tagName") == "SELECT":
        field.select_option(value)
    else:
        field.fill(value)


def _next(page: Any) -> None:
    """Run the next step (confirming it when the page asks) and wait until it is answered as expected."""
    done = page.locator("table.ctl-run tr.done").count()
    answered = ANSWERED.format(done=done)
    page.click("#ctl-seq-next")
    page.wait_for_function(f"() => document.querySelector('#ctl-confirm[open]') || {answered}", timeout=TIMEOUT_MS)
    if page.locator("#ctl-confirm[open]").count():
        page.click("#ctl-confirm-ok")
    page.wait_for_function(f"() => {answered}", timeout=TIMEOUT_MS)


def _current(page: Any, state: str) -> None:
    page.wait_for_selector(f'.ctl-state.current[data-state="{state}"]', timeout=TIMEOUT_MS)


def test_quick_commissioning_from_p0010_to_p3900_and_the_motor_turns(demo_server: tuple[str, Plant],
                                                                      page: Any) -> None:
    base, plant = demo_server
    store = plant.nodes[3].store
    url = f"{base}/sessions/demo-plant/nodes/3?tab=control"
    page.goto(url)
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    page.select_option("#ctl-seq", "mm-quick")
    page.click("#ctl-seq-start")
    page.wait_for_selector("#ctl-step-form[data-ref=P0010]", timeout=TIMEOUT_MS)
    page.wait_for_function("() => document.querySelector('#ctl-step-present').textContent !== '…'",
                           timeout=TIMEOUT_MS)
    assert page.locator("#ctl-step-present").inner_text().startswith("0")  # P0010 as the drive holds it
    _next(page)  # P0010 = 1, the proposal

    reloaded = False
    while page.is_enabled("#ctl-seq-next"):
        ref = _form_ref(page)
        if ref == "P0305" and not reloaded:  # a reload shows where the run stands
            reloaded = True
            page.reload()
            page.wait_for_selector("#ctl-step-form[data-ref=P0305]", timeout=TIMEOUT_MS)
            assert page.locator("table.ctl-run tr.done").count() == 4
        if ref == "P1120":
            form = page.locator("#ctl-step-form")
            assert "0 … 650 s" in form.inner_text()  # unit and range from the profile
            assert "Source:" in form.inner_text()
            _fill(page, ref, "9999")
            page.click("#ctl-seq-next")
            page.wait_for_selector("#ctl-run .error, #ctl-run [role=alert]", timeout=TIMEOUT_MS)
            refusal = page.locator("#ctl-run").inner_text()
            assert "650" in refusal and "9999" in refusal, refusal
            screenshot(page, "quick-commissioning-p1120-refused")
            assert _form_ref(page) == "P1120" and store.get_ref("P1120") == 10.0  # nothing written
        if ref in NAMEPLATE:
            _fill(page, ref, NAMEPLATE[ref])
        _next(page)

    page.wait_for_selector(".ok-note", timeout=TIMEOUT_MS)  # the check step: P0010 = 0 again
    assert page.locator("table.ctl-run tr.failed").count() == 0
    assert store.get_ref("P0010") == 0 and store.get_ref("P3900") == 3
    assert (store.get_ref("P0700"), store.get_ref("P1000")) == (6, 6)
    assert store.get_ref("P1120") == 2.0 and store.get_ref("P0311") == 1395
    screenshot(page, "quick-commissioning-done")

    _current(page, "switch_on_disabled")
    page.click("button[data-command=shutdown]")
    _current(page, "ready")
    page.click("button[data-command=enable_operation]")
    page.wait_for_selector("#ctl-confirm[open]", timeout=TIMEOUT_MS)
    page.click("#ctl-confirm-ok")
    _current(page, "operation_enabled")
    page.fill("#ctl-setpoint input[name=value]", "300")
    page.click("#ctl-setpoint button[type=submit]")
    page.wait_for_selector("#ctl-confirm[open]", timeout=TIMEOUT_MS)
    page.click("#ctl-confirm-ok")
    page.wait_for_function("() => parseFloat(document.querySelector('.ctl-value[data-ref=\"0x6044\"]')"
                           "?.textContent) > 0", timeout=TIMEOUT_MS * 2)
    screenshot(page, "quick-commissioning-motor-turns")
    page.click("button[data-command=quick_stop]")
