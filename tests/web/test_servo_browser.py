"""Any CiA 402 drive, in a real browser: a CiA 402 EDS written for this test (a linear axis in mm, not the shipped
servo's file) is uploaded on the Profiles page, a simulated drive built from it joins the bus, the Plant page scans
it, and its Control tab - the standard CiA 402 panel - homes it with method 35 and then 34, moves it to a target in
mm and back, runs it in profile velocity and jogs it, plotting position and velocity live. No word of the seed
drive families appears on the page."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.config import REPO_ROOT, settings
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, screenshot, serve_app, wait_until

pytestmark = [pytest.mark.browser, pytest.mark.usefixtures("patient_guard")]  # the flow, not the 2 s deadline

AXIS_EDS = REPO_ROOT / "tests" / "data" / "eds" / "linear_axis_cia402.eds"
PROFILE, NODE, SESSION = "linear_axis_cia402", 9, "servo-bench"
TIMEOUT_MS = 60_000  # a loaded 2-core machine: waits for conditions are generous
SEED_WORDS = ("MICROMASTER", "Siemens", "Lenze", "8400", "8200", "93XX", "motec", "EMF2178IB", "P0700", "P1000",
              "P1501", "C0135", "C0150", "C00866", "AIF", "r0027", "NSET")


@pytest.fixture
def server(tmp_path: Path) -> Iterator[tuple[str, Any]]:
    """A server whose plant bus has no drive yet (the test adds the uploaded one) and whose uploads go to a
    temporary directory."""
    plant_file = tmp_path / "servo-bench.json"
    plant_file.write_text(json.dumps({"name": "Servo bench", "bus": "virtual:x@500000", "nodes": []}))
    user_dir = tmp_path / "profiles"
    user_dir.mkdir()
    app = create_app(plant_file=plant_file, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", user_dir)
        with serve_app(app) as base_url:
            yield base_url, app


def _confirm(page: Any, values: str) -> None:
    """Confirm the question that names ``values`` and wait until the dialog no longer asks it. Not until the dialog
    is closed: a chain of questions (the mode, then the setpoint) reopens it with the next one as soon as the
    confirmed request is answered, and a loaded run does not look in between (it waited for a closed dialog while
    the next question stood open)."""
    asked = page.locator("#ctl-confirm[open] #ctl-confirm-values", has_text=values)
    asked.wait_for(timeout=TIMEOUT_MS)
    assert f"node {NODE}" in page.locator("#ctl-confirm-text").inner_text()
    question = asked.inner_text()
    page.click("#ctl-confirm-ok")
    page.wait_for_function("question => !document.querySelector('#ctl-confirm').open || "
                           "document.querySelector('#ctl-confirm-values').innerText !== question", arg=question,
                           timeout=TIMEOUT_MS)


def _value(page: Any, ref: str) -> str:
    value = page.locator(f'.ctl-value[data-ref="{ref}"]')
    return (value.text_content() if value.count() else "") or ""


def _until(page: Any, ref: str, wanted: str) -> None:
    assert wait_until(lambda: _value(page, ref) == wanted, TIMEOUT_MS / 1000), \
        f"{ref} shows {_value(page, ref)!r}, expected {wanted!r}"


def _plotted(page: Any, ref: str) -> tuple[int, float, float]:
    """(samples, lowest, highest) the live chart of ``ref`` holds (its last 30 s)."""
    box = page.locator(".ctl-plot", has=page.locator(f'.ctl-value[data-ref="{ref}"]'))
    assert box.locator("canvas").count() == 1
    shown = box.evaluate("box => [box.dataset.samples, box.dataset.min, box.dataset.max]")
    return int(shown[0] or 0), float(shown[1] or "nan"), float(shown[2] or "nan")


def _bit(page: Any, bit: int, on: bool = True) -> None:
    state = "on" if on else ""
    page.wait_for_function(f"() => document.querySelector('#ctl-sw-bits tr[data-bit=\"{bit}\"]').className === "
                           f"'{state}'", timeout=TIMEOUT_MS)  # an arrow function: the CSP refuses eval


def _read(page: Any, base: str, ref: str) -> Any:
    response = page.request.get(f"{base}/api/sessions/{SESSION}/nodes/{NODE}/parameters/{ref}")
    assert response.ok, response.text()
    return response.json()["value"]


def test_upload_scan_home_move_velocity_and_jog_a_cia402_axis(server: tuple[str, Any], page: Any) -> None:
    base, app = server
    page.goto(f"{base}/profiles")
    page.set_input_files("input[name=file]", str(AXIS_EDS))
    page.get_by_role("button", name="Upload").click()
    page.wait_for_selector("#upload-result .ok", timeout=TIMEOUT_MS)
    assert "LX-402 linear axis" in page.locator("table.profiles").inner_text()
    plant: Plant = next(iter(app.state.drivebench.plants.values()))
    plant.add_node(app.state.drivebench.registry.get(PROFILE), NODE)  # the drive is switched on on the bus

    page.goto(f"{base}/")
    page.get_by_role("button", name="Scan bus").click()
    page.wait_for_selector(f"#node-{SESSION}-{NODE}", timeout=TIMEOUT_MS)
    assert "LX-402 linear axis" in page.locator(f"#node-{SESSION}-{NODE}").inner_text()

    page.goto(f"{base}/sessions/{SESSION}/nodes/{NODE}?tab=control")
    page.wait_for_selector("#ctl-ws.good", timeout=TIMEOUT_MS)
    assert page.locator("#ctl-units").inner_text().startswith("Position in mm, velocity in mm/s")
    assert "0x605A = 2: slow down on quick-stop ramp" in page.locator("#ctl-qs-option").inner_text()
    assert page.locator("#ctl-inputs").inner_text().count("limit switch") == 2
    assert "No error" in page.locator("#ctl-error-code").inner_text()
    # no sequence of its own: the generic CiA 402 set-up from its standard objects (issue 30 item 3)
    assert page.locator("#ctl-seq option").evaluate_all("els => els.map(el => el.value)") == ["cia402-setup"]
    page.click("button[data-command=shutdown]")
    page.wait_for_selector('.ctl-state.current[data-state="ready"]', timeout=TIMEOUT_MS)
    page.click("button[data-command=switch_on]")
    page.wait_for_selector('.ctl-state.current[data-state="switched_on"]', timeout=TIMEOUT_MS)
    page.click("button[data-command=enable_operation]")
    _confirm(page, "0x6040 Controlword: 0x000F")
    page.wait_for_selector('.ctl-state.current[data-state="operation_enabled"]', timeout=TIMEOUT_MS)

    page.select_option("#ctl-home-method", "35")
    page.click("#ctl-home button[type=submit]")
    _confirm(page, "0x6098 Homing method: 35")
    _bit(page, 12)  # homing attained
    assert page.locator("#ctl-mode-display").inner_text() == "Homing (6)"
    _until(page, "0x6064", "0 mm")
    page.select_option("#ctl-home-method", "34")
    page.click("#ctl-home button[type=submit]")
    _confirm(page, "0x6098 Homing method: 34")
    assert wait_until(lambda: _read(page, base, "0x6098") == 34 and _read(page, base, "0x6041") & 0x1400 == 0x1400,
                      TIMEOUT_MS / 1000), "homing with method 34 never attained"
    assert 0 <= _read(page, base, "0x6064") <= 6  # at the next index pulse: at most one revolution (5 mm) on
    screenshot(page, "servo-homed")

    page.fill("#ctl-move input[name=target]", "50")
    page.fill("#ctl-move input[name=velocity]", "100")
    page.click("#ctl-move button[type=submit]")
    _confirm(page, "0x607A Target position: 50 mm")
    _until(page, "0x6064", "50 mm")
    _bit(page, 10)  # target reached
    page.fill("#ctl-move input[name=target]", "0")
    page.click("#ctl-move button[type=submit]")
    _confirm(page, "0x607A Target position: 0 mm")
    _until(page, "0x6064", "0 mm")
    assert wait_until(lambda: page.locator("#ctl-mode-display").inner_text() == "Profile position (1)",
                      TIMEOUT_MS / 1000), page.locator("#ctl-mode-display").inner_text()
    samples, lowest, highest = _plotted(page, "0x6064")
    assert lowest <= 0.5 and highest >= 49.5, (lowest, highest)  # the way to 50 mm and back is on the chart
    assert wait_until(lambda: _plotted(page, "0x6064")[0] > samples, TIMEOUT_MS / 1000)  # and it goes on: live

    page.fill("#ctl-velocity input[name=value]", "20")
    page.click("#ctl-velocity button[type=submit]")
    _confirm(page, "0x6060 Modes of operation: 3")  # the mode while enabled: asked with what it writes
    _confirm(page, "0x60FF Target velocity: 20 mm/s")  # then the target velocity, in the same dialog
    _until(page, "0x606C", "20 mm/s")
    # the display follows the drive's 0x6061 with the next status update
    assert wait_until(lambda: page.locator("#ctl-mode-display").inner_text() == "Profile velocity (3)",
                      TIMEOUT_MS / 1000), page.locator("#ctl-mode-display").inner_text()
    page.fill("#ctl-velocity input[name=value]", "0")
    page.click("#ctl-velocity button[type=submit]")
    _until(page, "0x606C", "0 mm/s")

    page.fill("#ctl-jog-speed", "10")
    page.click("button[data-jog='-1']")  # the press asks, naming what the jog sends
    page.wait_for_selector("#ctl-confirm[open]", timeout=TIMEOUT_MS)
    assert "-10 mm/s" in page.locator("#ctl-confirm-values").inner_text()
    page.locator("#ctl-confirm-ok").hover()
    page.mouse.down()  # held in the dialog: -10 mm/s
    _until(page, "0x606C", "-10 mm/s")
    page.mouse.up()  # released
    _until(page, "0x606C", "0 mm/s")
    page.click("#ctl-confirm button[value=cancel]")

    _, lowest, highest = _plotted(page, "0x606C")
    assert lowest <= -9.5 and highest >= 19.5, (lowest, highest)  # 20 mm/s and the -10 mm/s jog on the chart
    text = page.locator("body").inner_text()
    assert [word for word in SEED_WORDS if re.search(re.escape(word), text, re.IGNORECASE)] == []
    assert "null" not in text
    screenshot(page, "servo-control")
    page.click("button[data-command=quick_stop]")
    page.wait_for_selector('.ctl-state.current[data-state="switch_on_disabled"]', timeout=TIMEOUT_MS)
