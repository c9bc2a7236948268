"""Diagnostics in a real browser: the Remote tab (share link, live emergency, refused writes) and the Node
page's Diagnostics tab (heartbeat set-up written and verified, EMCY history, the device's diagnostic values)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, screenshot, serve_app


@pytest.fixture
def lenze_server(tmp_path: Path) -> Iterator[tuple[str, Plant]]:
    plant_file = tmp_path / "plant.json"
    plant_file.write_text(json.dumps({"name": "Line 2", "bus": "virtual:x@500000", "nodes": [
        {"node_id": 5, "profile": "lenze-8400-motec-canopen", "name": "Conveyor", "heartbeat_ms": 200},
        {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib", "name": "Fan", "heartbeat_ms": 200}]}))
    app = create_app(plant_file=plant_file, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        plants: dict[str, Plant] = app.state.drivebench.plants  # set by the app's start-up
        yield base_url, next(iter(plants.values()))


def test_share_link_view_is_live_and_read_only(lenze_server: tuple[str, Plant], browser: Any) -> None:
    base, plant = lenze_server
    engineer = browser.new_context(viewport={"width": 1440, "height": 900})
    page = engineer.new_page()
    page.goto(f"{base}/remote")
    page.fill("input[name=label]", "Lenze service, ticket 4711")
    page.click("text=Create share link")
    url = page.locator("input.share-url").input_value()
    assert "/remote/dbv_" in url
    assert page.locator("#share-links tbody tr", has_text="ticket 4711").count() == 1
    screenshot(page, "remote-engineer")

    remote = browser.new_context(viewport={"width": 1440, "height": 900})
    viewer = remote.new_page()
    viewer.goto(url)
    viewer.wait_for_selector("text=read-only view")
    viewer.wait_for_selector("tr[data-node='5'] >> text=Pre-operational")
    assert viewer.locator("button").count() == 0, "the remote view offers no action"
    plant.nodes[5].raise_emcy(0x3100, register=0x05)
    viewer.wait_for_selector("tr[data-node='5'] >> text=Supply voltage of standard device", timeout=10_000)
    assert viewer.locator("table.emcy", has_text="0x3100").count() == 1
    screenshot(viewer, "remote-viewer")

    viewer.goto(f"{base}/")
    assert "/remote/dbv_" in viewer.url, "a link holder lands on the remote view, not the engineer's screens"
    assert viewer.locator("header nav").count() == 0
    refused = viewer.request.post(f"{base}/api/sessions/line-2/nmt", data={"command": "start"})
    assert refused.status == 403
    assert "read-only" in refused.json()["detail"]
    plant.nodes[5].clear_emcy()
    engineer.close()
    remote.close()


def test_node_diagnostics_tab(lenze_server: tuple[str, Plant], page: Any) -> None:
    base, plant = lenze_server
    plant.nodes[5].raise_emcy(0x3100, register=0x05)
    page.goto(f"{base}/sessions/line-2/nodes/5?tab=diagnostics")
    page.wait_for_selector("#diag-heartbeat >> text=Producer time")
    assert page.locator("#diag-heartbeat input[name=time_ms]").first.input_value() == "200"
    page.wait_for_selector("#diag-emcy >> text=Supply voltage of standard device")

    consumer = page.locator("#diag-heartbeat form").nth(1)
    consumer.locator("input[name=producer_id]").fill("12")
    consumer.locator("input[name=time_ms]").fill("500")
    consumer.locator("button").click()
    page.wait_for_selector("#diag-heartbeat >> text=written and read back")
    assert plant.nodes[5].store.read(0x1016, 1) == ((12 << 16) | 500).to_bytes(4, "little")

    consumer = page.locator("#diag-heartbeat form").nth(1)
    consumer.locator("input[name=time_ms]").fill("100")  # shorter than node 12's 200 ms heartbeat
    consumer.locator("button").click()
    page.wait_for_selector("#diag-heartbeat .error >> text=must be longer than node 12's heartbeat")

    page.wait_for_selector("#diag-vendor table.vendor tbody tr", timeout=15_000)
    assert page.locator("#diag-vendor tbody tr").count() >= 3
    screenshot(page, "node-diagnostics")
    plant.nodes[5].clear_emcy()
