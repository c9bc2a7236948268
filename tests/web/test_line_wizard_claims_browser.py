"""A "New line" wizard page opened (or reloaded) while a step runs elsewhere (another tab, another DriveBench server
of the database): Chromium shows the step running, on which server and since when, and the step's result once it
has ended, without a reload. The step is held by the real simulator's axis answering slowly (a simulated fault)."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from drivebench.config import REPO_ROOT, settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import fresh_channel, serve_app
from tests.line_wizard_project import new_line_project

expect = pytest.importorskip("playwright.sync_api").expect

WIZARD = "/api/sessions/new-line/line-wizard"
SLOW_NODE = "/api/sessions/new-line/simulator/nodes/23/faults"
WAIT_MS = 60_000


@pytest.fixture
def line_server(app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    monkeypatch.setattr(settings, "sdo_timeout_s", 30.0)  # the slow axis answers, it does not time out
    app = create_app(plant_file=REPO_ROOT / "plants" / "new-line.json", plant_bus=f"virtual:{fresh_channel()}@500000")
    with serve_app(app) as url:
        yield url


def test_a_reloaded_page_shows_a_step_running_elsewhere_and_its_result_when_it_ends(line_server: str,
                                                                                   page: Any) -> None:
    with httpx.Client(base_url=line_server, timeout=120) as api:
        opened = api.post("/api/line-projects/import?filename=new-line.json",
                          content=json.dumps(new_line_project(ProfileRegistry())).encode())
        assert opened.status_code == 201, opened.text
        run_id = api.post(WIZARD, json={"project_id": opened.json()["id"]}).json()["id"]
        for name in ("scan", "assign"):
            assert confirmed(api, "POST", f"{WIZARD}/{run_id}/steps/{name}", json={}).status_code == 200
        assert api.put(SLOW_NODE, json={"latency_ms": 1500}).status_code == 200
        answers: list[httpx.Response] = []
        elsewhere = threading.Thread(target=lambda: answers.append(
            api.post(f"{WIZARD}/{run_id}/steps/boot_check", json={})), daemon=True)
        elsewhere.start()

        page.goto(f"{line_server}/sessions/new-line/line-wizard/{run_id}")
        expect(page.locator("#state-boot_check")).to_have_text("running", timeout=WAIT_MS)
        expect(page.locator("#claim-boot_check")).to_contain_text("(process ", timeout=WAIT_MS)
        expect(page.locator("#claim-boot_check")).to_contain_text(" since ")
        page.reload()  # the run resumes where it stands
        expect(page.locator("#state-boot_check")).to_have_text("running", timeout=WAIT_MS)

        assert api.put(SLOW_NODE, json={}).status_code == 200
        elsewhere.join(120)
        assert answers and answers[0].status_code == 200, answers
        expect(page.locator("#state-boot_check")).to_have_text("done", timeout=WAIT_MS)  # no reload
        expect(page.locator("#claim-boot_check")).to_have_text("")
        expect(page.locator("#lines-boot_check")).to_contain_text("The line matches its project.")
