"""Issue 31, display latency: the scope socket sends a viewer's rows as soon as they come (at most one message per
``MIN_INTERVAL_S``; what comes meanwhile, or while the viewer lags, in one message), and viewers who take the same
rows share one encoding of them. Two Scope pages in Chromium watch a free-run recording of the CiA 402 servo (node 7)
sampled by PDO at 1 ms, started over the HTTP API; one opens at the start, the other a little later (it gets the
last rows as a backlog first). Each page's socket gets every row in order, without a gap or a repeat, up to the last
sample the recording delivered before Stop."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import httpx
import pytest

from drivebench.config import settings
from drivebench.services.scope import runs
from drivebench.services.storage import database
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app, wait_until

AXIS = 7
API = "/api/sessions/demo-plant"
BODY = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x606C"}], "period_ms": 1,
        "length_s": 100.0, "trigger": {"mode": "free"}, "name": "every row"}
RECEIVED = """
(() => {
  const Native = window.WebSocket;
  window.scopeRowsSeen = [];
  window.WebSocket = class extends Native {
    constructor(url, protocols) {
      super(url, protocols);
      if (String(url).includes("/scope")) {
        this.addEventListener("message", (event) => {
          const message = JSON.parse(event.data);
          if (message.type === "rows") window.scopeRowsSeen.push(...message.rows.map((row) => row[0]));
        });
      }
    }
  };
})();
"""
"""Every row's sample number the page's scope socket receives, in the order it came."""


def _open(browser: Any, base: str) -> Any:
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    context.set_default_timeout(90_000)
    context.add_init_script(RECEIVED)
    page = context.new_page()
    page.goto(f"{base}/scope/demo-plant")
    return page


def _seen(page: Any) -> list[int]:
    return list(page.evaluate("window.scopeRowsSeen"))


@pytest.mark.timeout(300)
def test_two_pages_get_every_row_of_a_1_ms_recording_in_order(browser: Any, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    url = f"sqlite:///{tmp_path / 'scope.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    pages: list[Any] = []
    try:
        with serve_app(app) as base, httpx.Client(base_url=base, timeout=30) as http:
            pages.append(_open(browser, base))
            pages[0].wait_for_function("() => document.getElementById('scope-state').dataset.state === 'none'")
            started = confirmed(http, "POST", f"{API}/scope/run", json=BODY)
            assert started.status_code == 201 and started.json()["source"] == "pdo", started.text
            run = runs.current(app.state.drivebench.manager.get("demo-plant"))
            assert wait_until(lambda: len(_seen(pages[0])) >= 500, 60), "the first page receives rows"
            pages.append(_open(browser, base))
            assert wait_until(lambda: len(_seen(pages[1])) >= 1500 and len(_seen(pages[0])) >= 2500, 90), \
                [len(_seen(page)) for page in pages]
            stopped = http.post(f"{API}/scope/run/stop")
            assert stopped.status_code == 200 and stopped.json()["state"] == "stopped", stopped.text
            last = run.live[-1][0]
            for page in pages:
                assert wait_until(lambda page=page: _seen(page)[-1:] == [last], 30), (_seen(page)[-3:], last)
            for number, page in enumerate(pages, 1):
                seen = _seen(page)
                gaps = [(a, b) for a, b in itertools.pairwise(seen) if b != a + 1]
                assert not gaps, f"page {number}: rows out of order, missing or repeated at {gaps[:5]}"
            assert _seen(pages[0])[0] <= _seen(pages[1])[0], "the later page starts with the last rows, a backlog"
    finally:
        for page in pages:
            page.context.close()
        database.dispose(url)
