"""The Line project page in a real browser against the demo plant (issue 32): a broken project file is refused
with its line, a good one opened, the boot-up check shows each node's result, a node's concise DCF is previewed
decoded."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 30_000


@pytest.fixture
def server(app_db_url: str) -> Iterator[str]:
    """The demo plant on a bus and a database of this test's own."""
    with serve_app(create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000")) as url:
        yield url


def _identity(profile_id: str) -> dict[str, str]:
    identity = ProfileRegistry().get(profile_id).identity
    return {key: f"0x{value:08X}" for key, value in (("vendor_id", identity.vendor_id),
                                                       ("product_code", identity.product_code))
            if value is not None}


def project_file(tmp_path: Path) -> Path:
    project = {"schema_version": 1, "name": "Browser line", "nodes": [
        {"node_id": 5, "name": "Conveyor", "device": "lenze-8400-motec-canopen", "baud_kbit": 500,
         "identity": _identity("lenze-8400-motec-canopen"),
         "profile": {"id": "lenze-8400-motec-canopen", "sha256": ""}},
        {"node_id": 7, "name": "Axis", "device": "generic-cia402-servo", "baud_kbit": 500,
         "identity": {**_identity("generic-cia402-servo"), "revision_min": "0x00010000",
                      "revision_max": "0x0001FFFF"},
         "profile": {"id": "generic-cia402-servo", "sha256": ""},
         "parameter_set": {"name": "Axis set", "values": {"0x605A": 5}}, "pdo": {"0x1800.3": 250}},
        {"node_id": 21, "name": "Option", "device": "generic-cia402-servo", "baud_kbit": 500, "mandatory": False,
         "identity": _identity("generic-cia402-servo")}]}
    path = tmp_path / "browser-line.json"
    path.write_text(json.dumps(project, indent=2))
    return path


def test_open_a_project_check_the_line_and_preview_a_concise_dcf(page: Any, server: str, tmp_path: Path) -> None:
    page.goto(f"{server}/line-projects")
    expect(page.locator("#line-project-pick")).to_be_hidden()  # no empty list of projects
    expect(page.locator("#line-check")).to_be_disabled()  # the check and the wizard need a project
    expect(page.locator("#line-commission")).to_be_disabled()
    expect(page.locator("#line-wizard .line-needs-project")).to_have_text("Open a project file first.")
    broken = tmp_path / "broken.json"
    broken.write_text('{\n  "schema_version": 1,\n  "nodes": [\n    {"node_id": 5,, }\n  ]\n}\n')
    page.set_input_files("#line-file", str(broken))
    page.locator("#line-import button[type=submit]").click()
    expect(page.locator("#line-import-result .error")).to_contain_text("broken.json, line 4", timeout=WAIT_MS)

    page.set_input_files("#line-file", str(project_file(tmp_path)))
    page.locator("#line-import button[type=submit]").click()
    expect(page.locator("#line-opened")).to_contain_text("Browser line", timeout=WAIT_MS)
    expect(page.locator("#line-project-pick")).to_be_visible()
    expect(page.locator("#line-check")).to_be_enabled()
    expect(page.locator("#line-wizard .line-needs-project")).to_be_hidden()
    expect(page.locator("#line-export-json")).to_have_attribute("href", re.compile(r"/export\?format=json$"))

    page.locator("#line-check").click()
    expect(page.locator("#line-check-node-5")).to_contain_text("matches", timeout=WAIT_MS)
    expect(page.locator("#line-check-node-7")).to_contain_text("matches")
    expect(page.locator("#line-check-node-21")).to_contain_text("missing (optional)", timeout=WAIT_MS)
    expect(page.locator("#line-check-node-21")).to_contain_text("node 21 missing (optional)")
    expect(page.locator("#line-check-verdict")).to_have_text("The line matches its project.")

    page.locator("#line-dcf-node-7").click()
    table = page.locator("#line-dcf-table")
    expect(table).to_contain_text("Inhibit time", timeout=WAIT_MS)
    expect(table).to_contain_text("Quick stop option code")
    expect(table.locator("tbody tr")).to_have_count(2)
    expect(page.locator("#line-dcf-preview h3")).to_contain_text("2 entries")
    screenshot(page, "line-project")
