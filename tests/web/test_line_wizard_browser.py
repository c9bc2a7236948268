"""Issue 32's "Done when": Chromium commissions plants/new-line.json end to end with the "New line" wizard from a
line project file (uploaded through the Line project page): scan (confirmed for every device), a found device
dragged onto its planned node (and the list as the keyboard's way), assign, store, boot-up check, parameter sets,
the axis's firmware file checked and downloaded, the report as a page and as a JSON download; a reload in between
resumes the run. A screenshot of each step goes to test-artifacts/ (with DRIVEBENCH_SCREENSHOTS=docs/screenshots:
the README's pictures, cropped to the step's card)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.web.app import create_app
from tests.conftest import ARTIFACTS, fresh_channel, serve_app
from tests.line_wizard_project import AXIS_FIRMWARE, AXIS_VERSION, new_line_project

expect = pytest.importorskip("playwright.sync_api").expect

NEW_LINE = REPO_ROOT / "plants" / "new-line.json"
WAIT_MS = 60_000


@pytest.fixture
def line_server(app_db_url: str) -> Iterator[str]:
    with serve_app(create_app(plant_file=NEW_LINE, plant_bus=f"virtual:{fresh_channel()}@500000")) as url:
        yield url


def _shot(page: Any, selector: str, name: str) -> None:
    """The step's card only (small pictures for the README)."""
    folder = Path(os.environ.get("DRIVEBENCH_SCREENSHOTS") or ARTIFACTS)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"new-line-{name}.png"
    card = page.locator(selector)
    size = page.viewport_size
    height = card.bounding_box()["height"]
    if height + 120 > size["height"]:  # taller than the window: the sticky navigation would cover its top
        page.set_viewport_size({"width": size["width"], "height": int(height) + 200})
    card.screenshot(path=str(path))
    page.set_viewport_size(size)
    optipng = shutil.which("optipng")
    if os.environ.get("DRIVEBENCH_SCREENSHOTS") and optipng:  # the README's copies, losslessly smaller
        subprocess.run([optipng, "-quiet", "-o2", str(path)], check=True)


def _confirm(page: Any) -> str:
    asked = page.locator("#moving-confirm")
    expect(asked).to_be_visible(timeout=WAIT_MS)
    text = str(asked.inner_text())
    asked.get_by_role("button", name="Send it").click()
    return text


def _run(page: Any, step: str, *, asks: bool) -> str:
    page.locator(f".run-step[data-step='{step}']").click()
    asked = _confirm(page) if asks else ""
    expect(page.locator(f"#state-{step}")).to_have_text("done", timeout=WAIT_MS)
    return asked


def _wizard_opened(line_server: str, page: Any, tmp_path: Path) -> str:
    """The line project imported on the Line project page and its wizard opened: the run's address."""
    project = tmp_path / "new-line-project.json"
    project.write_text(json.dumps(new_line_project(ProfileRegistry()), indent=2), encoding="utf-8")
    page.goto(f"{line_server}/line-projects")
    page.set_input_files("#line-file", str(project))
    page.locator("#line-import button[type=submit]").click()
    expect(page.locator("#line-opened")).to_contain_text("Opened 'New line'", timeout=WAIT_MS)
    page.locator("#line-session").select_option("new-line")
    _shot(page, "#line-wizard", "1-commission")
    page.locator("#line-commission").click()
    expect(page.locator("h1")).to_have_text("New line", timeout=WAIT_MS)
    return str(page.url)


def test_the_steps_cannot_be_pressed_before_the_wizard_script_runs(line_server: str, page: Any,
                                                                   tmp_path: Path) -> None:
    """A loaded clean-clone run pressed Scan before the deferred line_wizard.js had bound it: nothing was asked or
    sent and the user would wait. The page sends the steps disabled; the script enables each once it is bound."""
    run_url = _wizard_opened(line_server, page, tmp_path)
    page.route("**/static/line_wizard.js", lambda route: route.abort())  # the script never comes
    page.goto(run_url)
    steps = page.locator(".run-step")
    assert steps.count() >= 6
    for index in range(steps.count()):
        expect(steps.nth(index)).to_be_disabled()
    page.unroute("**/static/line_wizard.js")
    page.goto(run_url)
    for index in range(steps.count()):
        expect(steps.nth(index)).to_be_enabled(timeout=WAIT_MS)


def test_chromium_commissions_the_new_line_with_the_wizard(line_server: str, page: Any, tmp_path: Path) -> None:
    page.set_viewport_size({"width": 1280, "height": 900})
    firmware = tmp_path / "axis.bin"
    firmware.write_bytes(AXIS_FIRMWARE)
    run_url = _wizard_opened(line_server, page, tmp_path)

    asked = _run(page, "scan", asks=True)
    assert "every node of the session" in asked and "reaches: all nodes on this bus" in asked
    expect(page.locator("#found-devices .found-device")).to_have_count(4, timeout=WAIT_MS)
    expect(page.locator("#lines-scan")).to_contain_text("4 devices without node ID found")
    _shot(page, "#step-scan", "2-scan")

    # proposed: every node has its device; the pump's is taken away by the list, then dragged back onto it
    pump = page.locator(".assign-choice[data-node='22']")
    expect(pump).to_have_value("0x00000BBB", timeout=WAIT_MS)
    pump.select_option("")
    expect(page.locator(".drop-zone[data-node='22']")).to_have_text("drop a device here", timeout=WAIT_MS)
    page.locator("#found-0x00000BBB").drag_to(page.locator(".drop-zone[data-node='22']"))
    expect(pump).to_have_value("0x00000BBB", timeout=WAIT_MS)
    expect(page.locator(".drop-zone[data-node='22']")).to_contain_text("MICROMASTER")
    _shot(page, "#step-assign", "3-assign-plan")

    asked = _run(page, "assign", asks=True)
    assert "serial 0x00000BBB -> node 22, 500000 bit/s" in asked
    expect(page.locator("#lines-assign")).to_contain_text("node 23 booted (boot-up telegram)")
    _shot(page, "#step-assign", "4-assigned")
    _run(page, "store", asks=True)
    expect(page.locator("#lines-store")).to_contain_text("configuration stored in the device")

    page.reload()  # the run is the server's: a reload shows where it stood
    expect(page.locator("#state-assign")).to_have_text("done", timeout=WAIT_MS)
    expect(page.locator("#state-store")).to_have_text("done")
    assert page.url == run_url

    _run(page, "boot_check", asks=False)
    expect(page.locator("#lines-boot_check")).to_contain_text("The line matches its project.")
    _shot(page, "#step-boot_check", "5-boot-check")
    _run(page, "sets", asks=False)
    expect(page.locator("#lines-sets")).to_contain_text("parameter set 'Axis set' downloaded")

    page.set_input_files(".firmware-file[data-node='23']", str(firmware))
    expect(page.locator("#firmware-23 .firmware-chosen")).to_contain_text("axis.bin checked", timeout=WAIT_MS)
    asked = _run(page, "program", asks=True)
    assert "node 23: 0x1F50 Program data" in asked
    expect(page.locator("#lines-program")).to_contain_text(f"reports firmware {AXIS_VERSION}, as the project expects")
    _shot(page, "#step-program", "6-program")
    expect(page.locator("#wizard-verdict")).to_have_text("every step done")

    with page.expect_download(timeout=WAIT_MS) as download:
        page.locator("#report-json").click()
    report = json.loads(Path(download.value.path()).read_text(encoding="utf-8"))
    assert report["complete"] is True
    assert [step["state"] for step in report["steps"]] == ["done"] * 6
    page.locator("#report-page").click()
    expect(page.locator("#report-verdict")).to_have_text("The line is commissioned: every step is done.",
                                                         timeout=WAIT_MS)
    expect(page.locator("#report-sets")).to_contain_text("done")
    _shot(page, "#wizard-report", "7-report")

    page.goto(f"{line_server}/line-projects")  # the run is found again from the Line project page
    page.locator("#line-session").select_option("new-line")
    resume = page.locator("#line-runs a").first
    expect(resume).to_contain_text("New line, 6 of 6 steps done", timeout=WAIT_MS)
    resume.click()
    expect(page.locator("#wizard-verdict")).to_have_text("every step done", timeout=WAIT_MS)
    assert page.url == run_url
