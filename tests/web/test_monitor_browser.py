"""The Monitor screen in a browser: counters move, the load chart renders, the trace shows decoded rows."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.services.monitoring import recording
from drivebench.web.app import create_app
from drivebench.web.ws.monitor import TRACE_PER_UPDATE
from tests.conftest import fresh_channel, screenshot, serve_app
from tests.web.monitor_plant import SESSION_ID, write_plant

CHANNEL = fresh_channel()


@pytest.fixture(scope="module")
def monitor_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    plant = write_plant(tmp_path_factory.mktemp("monitor"))
    recordings_dir = tmp_path_factory.mktemp("recordings")
    patch = pytest.MonkeyPatch()
    patch.setattr(recording, "recordings_dir", lambda: recordings_dir)
    app = create_app(plant_file=plant, plant_bus=f"virtual:{CHANNEL}@500000", latency="0ms")
    with serve_app(app) as base_url:
        yield base_url
    patch.undo()


def _frames(page: Any) -> int:
    return int(page.text_content("#stat-frames").replace(",", "") or 0)


def test_counters_move_chart_renders_trace_decodes(page: Any, monitor_server: str) -> None:
    page.goto(f"{monitor_server}/monitor")
    assert page.url.endswith(f"/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    page.wait_for_function("() => document.getElementById('stat-frames').textContent.replace(/,/g, '') > 0",
                           timeout=10_000)
    first = _frames(page)
    page.wait_for_function(f"() => Number(document.getElementById('stat-frames').textContent.replace(/,/g, '')) > "
                           f"{first}", timeout=10_000)
    assert page.locator("#services-body tr", has_text="Heartbeat / boot-up").count() == 1
    assert page.locator("#nodes-body tr", has_text="Conveyor (8400 motec)").count() == 1
    # The chart: uPlot's canvas, fed with one-second load points (> 0 %: heartbeats are on the bus).
    assert page.locator("#load-chart canvas").count() >= 1
    page.wait_for_function("() => window.monitorChart.data[0].length >= 2 && "
                           "Math.max(...window.monitorChart.data[1]) > 0", timeout=10_000)
    # Drag-zoom narrows the time axis and stays while updates arrive; a double-click goes back to the whole history.
    span = "window.monitorChart.scales.x.max - window.monitorChart.scales.x.min"
    assert page.evaluate(span) >= 60
    box = page.locator("#load-chart .u-over").bounding_box()
    assert box is not None
    page.mouse.move(box["x"] + box["width"] * 0.5, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.8, box["y"] + box["height"] / 2, steps=5)
    page.mouse.up()
    zoomed = page.evaluate(span)
    assert zoomed < 30
    time.sleep(0.5)  # several updates
    assert page.evaluate(span) == pytest.approx(zoomed)
    page.dblclick("#load-chart .u-over")
    page.wait_for_function(f"() => {span} >= 60", timeout=5_000)
    # Decoded trace rows; SDO traffic from reading the drive's own counters names the objects.
    page.click("text=Read device counters")
    page.wait_for_selector("#device-counters table", timeout=15_000)
    assert "Telegram counter SDO1 IN" in page.text_content("#device-counters")
    page.wait_for_selector("#trace-body td.decoded >> text=/read 0x5E97sub11 \\(C00360\\/11/", timeout=10_000)
    heartbeat = page.locator("#trace-body td.decoded", has_text="Pre-operational").first
    assert re.fullmatch(r"0x70[5C] \[1\] 7F", heartbeat.get_attribute("title") or "")
    path = screenshot(page, "monitor-live")
    assert path.exists()


def test_filter_pause_and_recording(page: Any, monitor_server: str, tmp_path: Path) -> None:
    page.goto(f"{monitor_server}/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    page.check("input[name=services][value=Heartbeat]")
    page.fill("input[name=nodes]", "12")
    page.click("#filter-form button[type=submit]")
    page.wait_for_selector("#trace-body tr", timeout=10_000)
    time.sleep(0.5)
    cobs = set(page.locator("#trace-body td.cob").all_text_contents())
    assert cobs == {"0x70C"}
    page.fill("input[name=cob_max]", "zz")
    page.click("#filter-form button[type=submit]")
    assert "COB-IDs decimal or 0x-hex" in page.text_content("#filter-result")
    page.fill("input[name=cob_max]", "0x7FF")
    page.fill("input[name=nodes]", "200")
    page.click("#filter-form button[type=submit]")
    page.wait_for_selector("#filter-result .error >> text=Filter not applied: nodes", timeout=5_000)
    screenshot(page, "monitor-filter-error")
    page.click("#filter-clear")
    page.click("#pause")
    page.wait_for_selector("#live-state.paused", timeout=5_000)
    time.sleep(0.3)  # updates already on their way are not drawn
    frozen = _frames(page)
    time.sleep(0.5)
    assert _frames(page) == frozen
    # This window's pause: the REST view (and every other viewer) stays live.
    assert page.request.get(f"{monitor_server}/api/sessions/{SESSION_ID}/monitor").json()["paused"] is False
    page.click("#pause")
    page.wait_for_selector("#live-state.live", timeout=5_000)
    page.select_option("#recordings select[name=format]", "pcapng")
    page.click("text=Start recording")
    page.wait_for_selector("text=Stop recording", timeout=5_000)
    time.sleep(0.5)
    page.click("text=Stop recording")
    page.wait_for_selector("#recordings .ok", timeout=5_000)
    with page.expect_download() as download_info:
        page.locator("#recordings a", has_text="Download").first.click()
    target = tmp_path / download_info.value.suggested_filename
    download_info.value.save_as(target)
    assert target.suffix == ".pcapng" and target.stat().st_size > 100
    screenshot(page, "monitor-recording")


def _cobs(page: Any) -> set[str]:
    return set(page.locator("#trace-body td.cob").all_text_contents())


def test_two_viewers_filter_and_pause_on_their_own(browser: Any, monitor_server: str) -> None:
    """Two browser windows on one session: one filters to node 12's heartbeats and pauses; the other stays
    unfiltered and live."""
    url = f"{monitor_server}/monitor/{SESSION_ID}"
    contexts = [browser.new_context(viewport={"width": 1440, "height": 900}) for _ in range(2)]
    try:
        filtered, other = (context.new_page() for context in contexts)
        for page in (filtered, other):
            page.goto(url)
            page.wait_for_selector("#live-state.live", timeout=10_000)
        filtered.check("input[name=services][value=Heartbeat]")
        filtered.fill("input[name=nodes]", "12")
        filtered.click("#filter-form button[type=submit]")
        filtered.wait_for_function("() => [...document.querySelectorAll('#trace-body td.cob')].length >= 3 && "
                                   "[...document.querySelectorAll('#trace-body td.cob')].every(c => c.textContent === "
                                   "'0x70C')", timeout=10_000)
        other.wait_for_selector("#trace-body td.cob >> text=0x705", timeout=10_000)
        time.sleep(0.5)
        assert _cobs(filtered) == {"0x70C"}
        assert {"0x705", "0x70C"} <= _cobs(other)
        assert filtered.locator("#cobs-body td.mono").all_text_contents() == ["0x70C"]
        assert "0x705" in other.locator("#cobs-body td.mono").all_text_contents()
        # Pause the filtered window: it freezes, the other goes on counting.
        filtered.click("#pause")
        filtered.wait_for_selector("#live-state.paused", timeout=5_000)
        time.sleep(0.3)
        frozen, moving = _frames(filtered), _frames(other)
        other.wait_for_function(f"() => Number(document.getElementById('stat-frames').textContent.replace(/,/g, '')) > "
                                f"{moving + 5}", timeout=10_000)
        assert other.text_content("#live-state") == "live"
        assert _frames(filtered) == frozen
        screenshot(filtered, "monitor-viewer-paused")
        screenshot(other, "monitor-viewer-live")
        filtered.click("#pause")
        filtered.wait_for_function("() => Number(document.getElementById('stat-frames').textContent"
                                   f".replace(/,/g, '')) > {frozen}", timeout=10_000)
        assert _cobs(filtered) == {"0x70C"}  # the filter survives the pause
    finally:
        for context in contexts:
            context.close()


def test_bus_state_badge_updates_live(page: Any, monitor_server: str) -> None:
    import can

    page.goto(f"{monitor_server}/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    assert page.text_content("#bus-state") == "bus active"
    with can.Bus(interface="virtual", channel=CHANNEL) as wire:
        wire.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes([0, 0x08, 0, 0, 0, 0, 101, 4])))
        page.wait_for_selector("#bus-state.bus-warning", timeout=10_000)
        assert page.text_content("#bus-state") == "bus warning · TEC 101 · REC 4"
        screenshot(page, "monitor-bus-warning")
        wire.send(can.Message(arbitration_id=0x040, is_error_frame=True, data=bytes(8)))
        page.wait_for_selector("#bus-state.bus-bus-off", timeout=10_000)
        assert page.text_content("#bus-state") == "bus-off"
        screenshot(page, "monitor-bus-off")
        wire.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes([0, 0x40, 0, 0, 0, 0, 0, 0])))
        page.wait_for_selector("#bus-state.bus-active", timeout=10_000)
    assert page.text_content("#bus-state") == "bus active · TEC 0 · REC 0"


def test_trace_length_is_chosen_and_remembered(page: Any, monitor_server: str) -> None:
    page.goto(f"{monitor_server}/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    assert page.input_value("#trace-length") == "500"
    page.wait_for_function("() => document.querySelectorAll('#trace-body tr').length > 5", timeout=10_000)
    page.select_option("#trace-length", "2000")
    assert page.evaluate("localStorage.getItem('drivebench.monitor.traceRows')") == "2000"
    page.wait_for_function("() => document.getElementById('trace-count').textContent.endsWith('of 2,000 rows')",
                           timeout=5_000)
    page.reload()
    page.wait_for_selector("#live-state.live", timeout=10_000)
    assert page.input_value("#trace-length") == "2000"
    # A short length trims what is kept at once.
    page.evaluate("localStorage.setItem('drivebench.monitor.traceRows', '500')")
    page.reload()
    page.wait_for_selector("#live-state.live", timeout=10_000)
    assert page.input_value("#trace-length") == "500"
    page.wait_for_function("() => document.querySelectorAll('#trace-body tr').length >= 3", timeout=10_000)
    page.evaluate("""() => {  // pretend many rows came: the body is trimmed to the chosen length on change
        const body = document.getElementById('trace-body');
        const row = body.rows[0].outerHTML;
        body.insertAdjacentHTML('afterbegin', row.repeat(700));
    }""")
    page.select_option("#trace-length", "2000")
    page.select_option("#trace-length", "500")
    assert page.locator("#trace-body tr").count() <= 500
    screenshot(page, "monitor-trace-length")


def test_trace_says_when_telegrams_came_faster_than_it_shows(page: Any, monitor_server: str) -> None:
    import can

    page.goto(f"{monitor_server}/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    page.wait_for_function("() => document.querySelectorAll('#trace-body tr').length > 2", timeout=10_000)
    assert page.locator("#trace-body tr.gap").count() == 0
    with can.Bus(interface="virtual", channel=CHANNEL) as wire:
        for counter in range(400):  # a burst: far more than one update's 50 rows
            wire.send(can.Message(arbitration_id=0x080, is_extended_id=False, data=bytes([counter % 240 + 1])))
    page.wait_for_selector("#trace-body tr.gap", timeout=10_000)
    assert "more telegrams than the trace shows" in page.text_content("#trace-body tr.gap")
    # The gap row comes with the update's full share of rows: the newest TRACE_PER_UPDATE telegrams, which are the
    # burst's and, on a loaded machine where the burst takes longer to send, the plant's heartbeats between them.
    after_gap = page.evaluate("""() => {
        const rows = [...document.querySelectorAll('#trace-body tr')];
        return rows.slice(rows.findIndex((row) => row.classList.contains('gap')) + 1)
            .filter((row) => !row.classList.contains('gap')).map((row) => row.cells[5].textContent);
    }""")
    assert len(after_gap) >= TRACE_PER_UPDATE
    assert sum(text.startswith("counter") for text in after_gap) > TRACE_PER_UPDATE // 2, after_gap
    page.uncheck("#trace-follow")
    page.evaluate("""() => {  // the gap row to the middle of the trace box (the page itself stays at the top)
        const box = document.getElementById('trace-scroll');
        box.scrollTop = document.querySelector('#trace-body tr.gap').offsetTop - box.clientHeight / 2;
    }""")
    page.evaluate("window.scrollTo(0, 0)")  # page.uncheck scrolled the window; the sticky bar would sit mid-shot
    screenshot(page, "monitor-trace-gap")
