"""The Control tab in a real browser: a first run of the MICROMASTER to "operation enabled" and back, with
the confirmation dialog, the highlighted state, live actual values and hold-to-run jog; and the 8200 vector
guided commissioning."""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable
from typing import Any

import pytest

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot, wait_until

TIMEOUT_MS = 10_000


pytestmark = pytest.mark.usefixtures("patient_guard")  # about the panel's flow, not the 2 s deadline
BLUE, RED = "rgb(11, 95, 165)", "rgb(198, 40, 40)"  # app.css --accent and --bad


def _control_from_can(plant: Plant) -> None:
    """The MICROMASTER takes commands and setpoint from CAN (set at the drive: through the tool, P0700/P1000 are
    writes that can move it, confirmed and kept alive; see test_moving_writes)."""
    for ref in ("P0700", "P1000"):
        plant.nodes[3].store.set_ref(ref, 6)


def _background(page: Any, selector: str) -> str:
    return str(page.locator(selector).evaluate("el => getComputedStyle(el).backgroundColor"))


def _current(page: Any, state: str) -> None:
    page.wait_for_selector(f'.ctl-state.current[data-state="{state}"]', timeout=TIMEOUT_MS)


def _target(page: Any, base: str, rpm: int) -> None:
    url = f"{base}/api/sessions/demo-plant/nodes/3/parameters/0x6042"
    assert wait_until(lambda: page.request.get(url).json()["value"] == rpm, TIMEOUT_MS / 1000), \
        f"0x6042 never became {rpm} rpm"


def _shown(page: Any, ref: str, done: Callable[[str], bool]) -> str:
    """Poll the live value of ``ref`` on the Control tab until ``done(text)``."""
    value = page.locator(f'.ctl-value[data-ref="{ref}"]')
    shown: list[str] = [""]

    def reached() -> bool:
        shown[0] = (value.text_content() if value.count() else "") or ""
        return done(shown[0])
    assert wait_until(reached, TIMEOUT_MS / 1000), f"{ref} shows {shown[0]!r}"
    return shown[0]


def test_first_run_to_operation_enabled_and_back(demo_server: tuple[str, Plant], page: Any) -> None:
    base, plant = demo_server
    plant.nodes[3].store.set_ref("P1120", 1.0)  # test-only: 1 s ramp instead of 10 s
    _control_from_can(plant)
    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    _current(page, "switch_on_disabled")
    assert page.locator('#ctl-sw-bits tr[data-bit="6"]').get_attribute("class") == "on"  # switch on disabled
    # Primary actions are blue like the rest of the app; only quick stop is red.
    assert _background(page, "button[data-command=enable_operation]") == _background(page, "#ctl-seq-next")
    assert _background(page, "#ctl-setpoint button[type=submit]") == BLUE
    assert _background(page, "button[data-command=quick_stop]") == RED
    assert page.get_by_label("Sequence").evaluate("el => el.id") == "ctl-seq"
    labels = page.evaluate("drivebenchClockLabels(null, [Date.now() / 1000])")
    assert re.fullmatch(r"\d\d:\d\d:\d\d", labels[0]), labels  # the chart's time axis reads hh:mm:ss
    page.click("button[data-command=shutdown]")
    _current(page, "ready")
    page.click("button[data-command=switch_on]")
    _current(page, "switched_on")
    page.click("button[data-command=enable_operation]")
    page.wait_for_selector("#ctl-confirm[open]")
    screenshot(page, "control-confirm")
    page.click("#ctl-confirm-ok")
    _current(page, "operation_enabled")
    page.wait_for_function("() => document.querySelector('#ctl-armed').textContent.startsWith('armed')",
                           timeout=TIMEOUT_MS)
    page.fill("#ctl-setpoint input[name=value]", "300")
    page.click("#ctl-setpoint button[type=submit]")
    page.click("#ctl-confirm-ok")
    page.wait_for_function("() => document.querySelector('.ctl-value[data-ref=\"0x6044\"]')"
                           "?.textContent.startsWith('300')", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-cw").inner_text() == "0x007F"
    _shown(page, "r0027", lambda text: text.endswith(" A") and float(text.split()[0]) > 0)  # running: current flows
    assert "Operation enabled" in page.locator("#ctl-sw-bits tr.on").all_inner_texts()[2]
    screenshot(page, "control-operation-enabled")
    page.click("button[data-jog='1']")  # the press asks, naming what the jog sends
    page.wait_for_selector("#ctl-confirm[open]", timeout=TIMEOUT_MS)
    assert "150 rpm" in page.locator("#ctl-confirm-values").inner_text()  # 10 % of 1500 rpm
    page.locator("#ctl-confirm-ok").hover()
    page.mouse.down()  # the dialog's button is the hold-to-run button: held, it jogs
    _target(page, base, 150)
    page.mouse.up()  # released: setpoint 0
    _target(page, base, 0)
    page.click("#ctl-confirm button[value=cancel]")
    page.click("button[data-command=disable_operation]")
    _current(page, "switched_on")
    page.click("button[data-command=shutdown]")
    _current(page, "ready")
    page.wait_for_function("() => document.querySelector('#ctl-armed').textContent === 'not armed'", timeout=TIMEOUT_MS)
    screenshot(page, "control-back-to-ready")
    _shown(page, "r0027", lambda text: text == "0 A")  # pulses inhibited: no current


def test_back_to_the_control_tab_gives_a_working_panel(demo_server: tuple[str, Plant], page: Any) -> None:
    """Back from another tab restores htmx's snapshot of the page: the panel in it is set up again (socket,
    buttons), not a dead copy whose Shutdown and Quick stop do nothing."""
    from tests.web.test_ux_browser import Watch

    base, plant = demo_server
    _control_from_can(plant)
    watch = Watch(page, base)
    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    _current(page, "switch_on_disabled")
    page.click("nav.tabs a[data-tab=info]")
    page.wait_for_selector("#node-tab[data-tab=info]", timeout=TIMEOUT_MS)
    with page.expect_websocket(lambda socket: "/control?panel=" in socket.url, timeout=TIMEOUT_MS):
        page.go_back()  # the restored panel opens its own status socket
    page.wait_for_selector("#node-tab[data-tab=control]", timeout=TIMEOUT_MS)
    page.click("button[data-command=shutdown]")
    _current(page, "ready")
    page.click("button[data-command=disable_voltage]")
    _current(page, "switch_on_disabled")
    screenshot(page, "control-after-back")
    assert watch.problems == []


def test_guided_commissioning_8200_vector(demo_server: tuple[str, Plant], page: Any) -> None:
    base, _ = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/12?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    assert "NSET1-JOG1 (C0037 = 20 Hz)" in page.locator("#ctl-jog-how").inner_text()  # the device's own jog
    page.click("#ctl-seq-start")
    page.wait_for_selector("table.ctl-run")
    while page.is_enabled("#ctl-seq-next"):
        done = page.locator("table.ctl-run tr.done").count()
        answered = f"document.querySelectorAll('table.ctl-run tr.done, table.ctl-run tr.failed').length > {done}"
        page.click("#ctl-seq-next")
        page.wait_for_function(f"() => document.querySelector('#ctl-confirm[open]') || {answered}", timeout=TIMEOUT_MS)
        if page.locator("#ctl-confirm[open]").count():
            page.click("#ctl-confirm-ok")
        page.wait_for_function(f"() => {answered}", timeout=TIMEOUT_MS)
    assert page.locator("table.ctl-run tr.failed").count() == 0
    assert "answered as the manual expects" in page.locator(".ok-note").inner_text()
    assert "→ 0x60C 23 FE 5F 00 30 75 00 00" in page.locator("table.ctl-run").inner_text()
    _current(page, "operation_inhibited")
    screenshot(page, "control-commissioning-8200")


def test_second_panel_watches_the_drive_the_first_holds(demo_server: tuple[str, Plant], browser: Any) -> None:
    """Anna's panel arms the MICROMASTER; Ben's panel on the same node names her, offers only the stopping
    commands, and closing it leaves her drive running. Closing Anna's panel quick-stops the drive."""
    base, plant = demo_server
    _control_from_can(plant)
    url = f"{base}/sessions/demo-plant/nodes/3?tab=control"
    anna_context = browser.new_context(viewport={"width": 1440, "height": 900})
    ben_context = browser.new_context(viewport={"width": 1440, "height": 900})
    try:
        anna, ben = anna_context.new_page(), ben_context.new_page()
        for page in (anna, ben):
            page.goto(url)
            page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
            _current(page, "switch_on_disabled")
        anna.fill("#ctl-operator", "Anna")
        anna.press("#ctl-operator", "Tab")
        anna.click("button[data-command=shutdown]")
        _current(anna, "ready")
        anna.click("button[data-command=enable_operation]")
        anna.click("#ctl-confirm-ok")
        _current(anna, "operation_enabled")
        anna.wait_for_function("() => document.querySelector('#ctl-holder').textContent.startsWith('This panel holds')",
                               timeout=TIMEOUT_MS)
        ben.wait_for_selector("#ctl-holder.watching", timeout=TIMEOUT_MS)
        assert ben.locator("#ctl-holder").inner_text().startswith("Held by Anna at 127.0.0.1 since ")
        assert ben.locator("#ctl-panels").inner_text() == "2 panels open"
        assert ben.is_disabled("button[data-command=enable_operation]")
        assert ben.is_disabled("#ctl-setpoint button[type=submit]") and ben.is_disabled("button[data-jog='1']")
        assert ben.is_enabled("button[data-command=quick_stop]")
        screenshot(ben, "control-watching-panel")
        ben_context.close()
        anna.wait_for_function("() => document.querySelector('#ctl-panels').textContent === '1 panel open'",
                               timeout=TIMEOUT_MS)
        anna.wait_for_timeout(500)  # a trip would show at once; none must come
        assert anna.locator("#ctl-trip").is_hidden()
        _current(anna, "operation_enabled")
        screenshot(anna, "control-holding-panel")
        anna_context.close()
        status_url = f"{base}/api/sessions/demo-plant/nodes/3/control"
        checker = browser.new_context()
        status: dict[str, Any] = {}

        def stopped() -> bool:
            status.update(checker.request.get(status_url).json())
            return status["state"] == "switch_on_disabled"
        assert wait_until(stopped, TIMEOUT_MS / 1000), f"the drive stays in {status['state_label']} after Anna left"
        assert "held by Anna" in status["last_trip"] and "disconnected" in status["last_trip"]
        checker.close()
    finally:
        for context in (anna_context, ben_context):
            with contextlib.suppress(Exception):
                context.close()


def test_node_without_profile_shows_an_empty_state(demo_server: tuple[str, Plant], page: Any) -> None:
    base, _ = demo_server
    assert page.request.post(f"{base}/api/sessions/demo-plant/nodes", data={"node_id": 40}).ok
    page.goto(f"{base}/sessions/demo-plant/nodes/40?tab=control")
    empty = page.locator("#ctl-empty")
    empty.wait_for(timeout=TIMEOUT_MS)
    assert "has no device profile: assign one on the Plant page" in empty.inner_text()
    assert page.locator("#control-tab .error").count() == 0  # not an error: nothing went wrong
    screenshot(page, "control-no-profile")


@pytest.mark.parametrize(("node_id", "current", "dc_bus", "source"), [
    (3, "r0027", "r0026", "MICROMASTER 440 parameter list"),
    (5, "C00054", "C00053", "ASSUMED"),
    (12, "C0054", "C0053", "8200 vector code table")])
def test_every_demo_node_plots_current_and_dc_bus(demo_server: tuple[str, Plant], page: Any, node_id: int, current: str,
                                                  dc_bus: str, source: str) -> None:
    base, _ = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/{node_id}?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    assert _shown(page, current, lambda text: text.endswith(" A")) == "0 A"  # at rest
    volts = float(_shown(page, dc_bus, lambda text: text.endswith(" V")).split()[0])
    assert 540 <= volts <= 566
    for ref in (current, dc_bus):  # a chart with its unit on the axis, not just a number
        plot = page.locator(".ctl-plot", has=page.locator(f'.ctl-value[data-ref="{ref}"]'))
        expect_canvas = plot.locator("canvas")
        assert expect_canvas.count() == 1 and expect_canvas.bounding_box()["width"] > 200
    sources = page.locator("#ctl-sources").inner_text()
    assert f"{current} = 0x" in sources and f"{dc_bus} = 0x" in sources and source in sources
    if node_id == 3:
        assert page.locator("#ctl-missing").count() == 0  # the MICROMASTER has all five
    else:
        assert "Not available: Torque" in page.locator("#ctl-missing").inner_text()
    screenshot(page, f"control-actuals-node{node_id}")


def test_demo_axis_has_the_standard_cia402_panel_and_the_seed_drives_keep_theirs(demo_server: tuple[str, Plant],
                                                                                page: Any) -> None:
    """Node 7 of the demo plant (generic CiA 402 servo): its own Control tab with the CiA 402 motion controls, none
    of the seed drives' words; node 3 keeps the MICROMASTER's."""
    base, _ = demo_server
    page.goto(f"{base}/sessions/demo-plant/nodes/7?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-motion").count() == 1 and page.locator("#ctl-home-method").count() == 1
    assert page.locator("input[name=ctl-mode][value='7']").count() == 1  # 0x6502 bit 6: interpolated position
    assert page.locator("#ctl-cyclic").count() == 1  # streamed by SYNC + RPDO as modes 8/9/10
    assert page.locator("#ctl-home-method option").count() == 32  # the methods 0x60E3 lists
    assert page.locator("#ctl-units").inner_text().startswith("Position in °, velocity in rpm")
    tab = page.locator("#control-tab").inner_text()
    assert not [word for word in ("MICROMASTER", "Lenze", "P0700", "8400", "EMF2178IB") if word in tab]
    assert page.locator("#ctl-seq option").evaluate_all("els => els.map(el => el.value)") == ["cia402-setup"]
    page.goto(f"{base}/sessions/demo-plant/nodes/3?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-motion").count() == 0
    assert "P0700 = 6" in page.locator("#control-tab").inner_text()
