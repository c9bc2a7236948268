"""Issue 31 item 1: the compact scope panel on a node's Control tab, in Chromium, German, 1024 px: it offers the
simulated CiA 402 servo's (node 7) actual values that fit one TPDO beside its status word, starts a free run over
the same run API as the Scope page (sampling by PDO: the page's confirmation dialog names the SYNC and NMT start),
draws the live trace small, Stop stores it and puts every TPDO and SYNC setting back, and its link opens that
recording on the Scope page. The page has no sideways scroll."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app, wait_until

SERVO = 7
WAIT_MS = 90_000
PANEL = "document.getElementById('scope-panel')"


def pdo_settings(base: str, node: int = SERVO) -> dict[str, object]:
    """Every SYNC (0x1005, 0x1006) and TPDO setting (0x18xx, 0x1Axx) of ``node``, read through the parameters API."""
    with httpx.Client(base_url=f"{base}/api/sessions/demo-plant/nodes/{node}", timeout=30) as http:
        listed = http.get("/parameters").json()["parameters"]
        refs = [p["ref"] for p in listed if int(p["index"], 16) in (0x1005, 0x1006)
                or 0x1800 <= int(p["index"], 16) <= 0x19FF or 0x1A00 <= int(p["index"], 16) <= 0x1BFF]
        answer = http.post("/parameters:read", json={"refs": refs})
        assert answer.status_code == 200 and refs, answer.text
        return {item["ref"]: item["value"]["raw"] if item["ok"] else item["error"]["detail"]
                for item in answer.json()["items"]}


@pytest.fixture
def panel_server(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[str, Plant]]:
    url = f"sqlite:///{tmp_path / 'panel.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        yield base_url, app.state.drivebench.plants["demo-plant"]
    database.dispose(url)


@pytest.mark.timeout(300)  # 70 s on a loaded 2-core machine (the suite's 120 s is for a hang)
def test_the_control_tab_records_its_node_small_and_opens_the_run_on_the_scope_page(
        page: Any, panel_server: tuple[str, Plant]) -> None:
    base, _plant = panel_server
    before = pdo_settings(base)
    page.context.set_default_timeout(WAIT_MS)  # not Playwright's 30 s: a loaded machine's first page takes longer
    page.set_viewport_size({"width": 1024, "height": 900})
    page.goto(f"{base}/language/de?next=/")
    page.goto(f"{base}/sessions/demo-plant/nodes/{SERVO}?tab=control")
    panel = page.locator("#scope-panel")
    panel.wait_for(timeout=WAIT_MS)
    offered = panel.locator("input[name=channel]")
    assert 2 <= offered.count() <= 4
    refs = [offered.nth(i).get_attribute("value") for i in range(offered.count())]
    assert refs[-1] == "0x6041" and "0x6064" in refs, f"position, and the status word marks drive states: {refs}"
    page.select_option("#scope-panel-form [name=period_ms]", "20")
    page.fill("#scope-panel-form [name=length_s]", "5")
    page.click("#scope-panel-start")
    dialog = page.locator("#moving-confirm")
    dialog.wait_for(state="visible", timeout=WAIT_MS)
    assert "SYNC" in dialog.text_content(), dialog.text_content()
    dialog.locator("button[value=ok]").click()
    page.wait_for_function(f"() => {PANEL}.scopeChart && {PANEL}.scopeChart.data[0].length >= 10", timeout=WAIT_MS)
    with httpx.Client(base_url=f"{base}/api/sessions/demo-plant", timeout=30) as http:
        running = http.get("/scope/run").json()
    assert running["state"] == "recording" and running["source"] == "pdo", running
    assert [c["ref"] for c in running["channels"]] == refs and {c["node"] for c in running["channels"]} == {SERVO}
    assert page.text_content("#scope-panel-state") == "zeichnet auf", "the state in German"
    assert page.evaluate("document.documentElement.scrollWidth <= window.innerWidth"), "no sideways scroll at 1024"
    screenshot(page, "scope-panel-de-1024")

    page.click("#scope-panel-stop")
    page.wait_for_function(f"() => {PANEL}.querySelector('#scope-panel-open').href.includes('recording=')",
                           timeout=WAIT_MS)
    with httpx.Client(base_url=f"{base}/api/sessions/demo-plant", timeout=30) as http:
        stopped = http.get("/scope/run").json()
    assert stopped["state"] == "stopped" and stopped["recording_id"], stopped
    assert stopped["restored"], "what was put back, in words"
    assert pdo_settings(base) == before, "every TPDO and SYNC setting is back"

    page.click("#scope-panel-open")
    page.wait_for_url(f"**/scope/demo-plant?recording={stopped['recording_id']}", timeout=WAIT_MS)
    with httpx.Client(base_url=base, timeout=30) as http:
        count = http.get(f"/api/scope/recordings/{stopped['recording_id']}").json()["count"]
    page.wait_for_function(f"() => window.scopeChart && window.scopeChart.data[0].length === {count}",
                           timeout=WAIT_MS)
    assert "7" in page.text_content("#plot-what")


def test_the_panel_says_in_words_why_the_8400_motec_is_polled(page: Any, panel_server: tuple[str, Plant]) -> None:
    """Issue 31's open point: the panel showed only "SDO polling". It lists the plan as the Scope page has it: the
    8400 motec's TPDOs send the static port words, and its current and DC-bus voltage are no TPDO's (in German)."""
    base, _plant = panel_server
    page.set_viewport_size({"width": 1024, "height": 900})
    page.goto(f"{base}/language/de?next=/")
    page.goto(f"{base}/sessions/demo-plant/nodes/5?tab=control")
    page.locator("#scope-panel-form").wait_for(timeout=WAIT_MS)
    page.click("#scope-panel-start")  # polling alone moves nothing: no confirmation
    plan = page.locator("#scope-panel-plan li")
    plan.first.wait_for(timeout=WAIT_MS)
    lines = [plan.nth(i).text_content() for i in range(plan.count())]
    assert any("TPDO1 sendet das statische Mapping des Geräts (C00868/1" in line for line in lines), lines
    assert any("C00054, C00053 gepollt" in line for line in lines), lines
    page.click("#scope-panel-stop")
    page.wait_for_function(f"() => {PANEL}.querySelector('#scope-panel-open').href.includes('recording=')",
                           timeout=WAIT_MS)


def test_a_share_link_opens_the_scope_page_read_only_in_a_browser(browser: Any,
                                                                  panel_server: tuple[str, Plant]) -> None:
    """Issue 31 item 4: the link holder's Scope page lists the stored recordings with Open and the exports but no
    Delete, has no picker and no Start, draws an opened recording, and the page's script runs without an error."""
    base, _plant = panel_server
    with httpx.Client(base_url=f"{base}/api", timeout=30) as http:
        body = {"channels": [{"node": 5, "ref": "C00868/2"}], "period_ms": 50, "length_samples": 10,
                "trigger": {"mode": "free"}, "name": "for the link"}  # polled: nothing to confirm
        assert http.post("/sessions/demo-plant/scope/run", json=body).status_code == 201
        assert wait_until(lambda: http.get("/sessions/demo-plant/scope/run").json()["captures"] >= 1, 60)
        stopped = http.post("/sessions/demo-plant/scope/run/stop").json()
        assert stopped["recording_id"], stopped
        token = http.post("/share-links", json={"ttl_minutes": 5, "shows": ["scope"]}).json()["token"]
    context = browser.new_context(viewport={"width": 1024, "height": 900})
    context.set_default_timeout(WAIT_MS)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        page.goto(f"{base}/remote/{token}")
        page.click(".remote-scope a")
        page.wait_for_url("**/scope/demo-plant", timeout=WAIT_MS)
        row = page.locator("#scope-recordings tbody tr", has_text="for the link")
        row.wait_for(timeout=WAIT_MS)
        assert row.locator("button", has_text="Open").count() == 1 and row.locator("a", has_text="CSV").count() == 1
        assert row.locator(".delete-recording").count() == 0 and page.locator("#scope-start").count() == 0
        row.locator("button", has_text="Open").click()
        page.wait_for_function("() => window.scopeChart && window.scopeChart.data[0].length >= 10", timeout=WAIT_MS)
        assert "for the link" in page.text_content("#plot-what")
        screenshot(page, "scope-share-link-read-only")
    finally:
        context.close()
    assert errors == [], errors


def _fills(chart: str) -> str:
    """The trace of ``chart`` holds more than ``after`` + 10 samples, in time order (one recording's)."""
    return (f"(after) => {{ const c = {chart}; if (!c) return false; const times = c.data[0];"
            " return times.length > after + 10 && times.every((t, i) => !i || t > times[i - 1]); }")


def test_every_watching_page_starts_a_new_trace_for_the_next_recording_of_the_same_channels(
        page: Any, panel_server: tuple[str, Plant]) -> None:
    """Issue 29: the pages told recordings apart by their channels, so a page watching while a recording was stopped
    and the next one of the same channels started (over the API, from another page) drew the new samples after the
    old ones, time going back to 0. Both the Control tab's panel and the Scope page start a trace of their own for
    each recording (its id)."""
    base, _plant = panel_server
    page.context.set_default_timeout(WAIT_MS)
    page.goto(f"{base}/sessions/demo-plant/nodes/{SERVO}?tab=control")
    page.locator("#scope-panel").wait_for(timeout=WAIT_MS)
    scope_page = page.context.new_page()
    scope_page.goto(f"{base}/scope/demo-plant")
    states = ((page, "#scope-panel-state"), (scope_page, "#scope-state"))
    for watching, state in states:
        watching.wait_for_function(f"() => document.querySelector('{state}').dataset.state === 'none'",
                                   timeout=WAIT_MS)
    charts = ((page, f"{PANEL}.scopeChart"), (scope_page, "window.scopeChart"))
    body = {"channels": [{"node": 5, "ref": "C00868/2"}], "period_ms": 50, "length_samples": 1000,
            "trigger": {"mode": "free"}, "name": "the same channels again"}  # polled: nothing to confirm
    shown = [0, 0]
    with httpx.Client(base_url=f"{base}/api/sessions/demo-plant", timeout=30) as http:
        for _run in range(2):
            assert http.post("/scope/run", json=body).status_code == 201
            for (watching, chart), after in zip(charts, shown, strict=True):
                watching.wait_for_function(_fills(chart), arg=after, timeout=60_000)
            assert http.post("/scope/run/stop").status_code == 200
            for watching, state in states:
                watching.wait_for_function(f"() => document.querySelector('{state}').dataset.state === 'stopped'",
                                           timeout=WAIT_MS)
            shown = [watching.evaluate(f"{chart}.data[0].length") for watching, chart in charts]


def test_a_press_on_start_before_the_panel_script_ran_neither_reloads_the_page_nor_is_lost(
        page: Any, panel_server: tuple[str, Plant]) -> None:
    """A stop's CI run on a loaded machine pressed Start after the form showed but before scope_panel.js had bound
    it: the browser sent the form itself (a GET of the node page with the channels in the address, another tab) and
    the recording never started. Start now comes disabled and the script enables it; every script-driven form is
    marked data-no-submit, so even a press that gets through reloads nothing."""
    base, _plant = panel_server
    held: list[Any] = []
    page.route("**/static/scope_panel.js", lambda route: held.append(route))  # the script is held back
    page.goto(f"{base}/sessions/demo-plant/nodes/5?tab=control")
    start = page.locator("#scope-panel-start")
    start.wait_for(timeout=WAIT_MS)
    assert start.is_disabled(), "Start is usable before the script that handles it has run"
    page.evaluate("document.getElementById('scope-panel-form').requestSubmit()")  # a submit that gets through
    page.wait_for_timeout(500)
    assert "channel=" not in page.url and page.url.endswith("?tab=control"), page.url
    for _ in range(300):  # the route handler runs while Playwright waits, not during a plain sleep
        if held:
            break
        page.wait_for_timeout(100)
    assert held, "the page asked for scope_panel.js"
    held[0].continue_()
    page.locator("#scope-panel-start:enabled").wait_for(timeout=WAIT_MS)
    page.click("#scope-panel-start")
    page.locator("#scope-panel-plan li").first.wait_for(timeout=WAIT_MS)
    page.click("#scope-panel-stop")
    page.wait_for_function(f"() => {PANEL}.querySelector('#scope-panel-open').href.includes('recording=')",
                           timeout=WAIT_MS)
