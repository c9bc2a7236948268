"""The Monitor screen in a browser: counters move, the load chart renders, the trace shows decoded rows."""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import uvicorn

from drivebench.services import recording
from drivebench.web.app import create_app
from tests.conftest import _free_port, fresh_channel, screenshot
from tests.web.monitor_plant import SESSION_ID, write_plant


@pytest.fixture(scope="module")
def monitor_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    plant = write_plant(tmp_path_factory.mktemp("monitor"))
    recordings_dir = tmp_path_factory.mktemp("recordings")
    patch = pytest.MonkeyPatch()
    patch.setattr(recording, "recordings_dir", lambda: recordings_dir)
    port = _free_port()
    app = create_app(plant_file=plant, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.time() + 20
    while not server.started and time.time() < deadline:
        time.sleep(0.05)
    assert server.started, "the server did not start"
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=10)
    patch.undo()


def _frames(page: Any) -> int:
    return int(page.text_content("#stat-frames").replace(",", "") or 0)


def test_counters_move_chart_renders_trace_decodes(page: Any, monitor_server: str) -> None:
    page.goto(f"{monitor_server}/monitor")
    assert page.url.endswith(f"/monitor/{SESSION_ID}")
    page.wait_for_selector("#live-state.live", timeout=10_000)
    page.wait_for_function("document.getElementById('stat-frames').textContent.replace(/,/g, '') > 0",
                           timeout=10_000)
    first = _frames(page)
    page.wait_for_function(f"Number(document.getElementById('stat-frames').textContent.replace(/,/g, '')) > {first}",
                           timeout=10_000)
    assert page.locator("#services-body tr", has_text="Heartbeat / boot-up").count() == 1
    assert page.locator("#nodes-body tr", has_text="Conveyor (8400 motec)").count() == 1
    # The chart: uPlot's canvas, fed with one-second load points (> 0 %: heartbeats are on the bus).
    assert page.locator("#load-chart canvas").count() >= 1
    page.wait_for_function("window.monitorChart.data[0].length >= 2 && Math.max(...window.monitorChart.data[1]) > 0",
                           timeout=10_000)
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
    page.wait_for_function(f"{span} >= 60", timeout=5_000)
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
    page.click("#filter-clear")
    page.click("#pause")
    page.wait_for_selector("#live-state.paused", timeout=5_000)
    frozen = _frames(page)
    time.sleep(0.5)
    assert _frames(page) == frozen
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
