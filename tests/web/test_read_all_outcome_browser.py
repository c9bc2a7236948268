"""The Parameters tab says what a read-all could not read (issue 28 item 5), in a real browser: the job line ends
"incomplete" with the counts, the bar is not full, and the rows not read are marked."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 60_000


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        yield base_url


def test_read_all_of_a_node_that_does_not_answer_says_so(server: str, page: Any) -> None:
    response = page.request.post(server + "/api/sessions/demo-plant/nodes",
                                 data={"node_id": 20, "profile_id": "generic-cia402-servo"})
    assert response.status == 201, response.text()
    page.goto(server + "/sessions/demo-plant/nodes/20")
    page.get_by_role("button", name="Read all").click()
    text = page.locator(".job-text")
    expect(text).to_contain_text("incomplete", timeout=WAIT_MS)
    expect(text).to_contain_text("not read")
    expect(text).to_contain_text("Node 20 did not answer")
    bar = page.locator(".job progress")
    assert bar.evaluate("el => el.value") < bar.evaluate("el => el.max")
    expect(page.locator("tr[data-ref='0x6041'] .read-failed")).to_contain_text("not read", timeout=WAIT_MS)
