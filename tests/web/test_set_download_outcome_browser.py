"""The Sets page says what a download could not write (issue 28 item 5), in a real browser: the report ends
"incomplete" with written / verified / failed / not written, its bar is not full, and the failed row says why. The
demo plant on a server of its own (temporary database); the simulator leaves node 5's first write unanswered."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.conftest import screenshot, wait_for_value
from tests.web.conftest import demo_server_with_own_db

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 60_000
SESSION = "/api/sessions/demo-plant"


@pytest.fixture(scope="module")
def sets_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with demo_server_with_own_db(tmp_path_factory, "sets-db") as base_url:
        yield base_url


def _ok(answer: Any) -> Any:
    assert answer.ok, answer.text()
    return answer.json() if answer.status != 204 else None


def _changed_set(page: Any, server: str) -> int:
    """Node 5 uploaded into a set whose C00039/1 and C00088 differ from the node (C00039/1 is written first)."""
    job = _ok(page.request.post(server + "/api/parameter-sets/upload",
                                data={"session_id": "demo-plant", "node_id": 5, "name": "Conveyor"}))

    def finished() -> dict[str, Any] | None:
        now: dict[str, Any] = _ok(page.request.get(f"{server}/api/parameter-sets/jobs/{job['id']}"))
        return now if now["state"] != "running" else None
    set_id = int(wait_for_value(finished, 120, "the upload ends")["set_id"])
    _ok(page.request.patch(f"{server}/api/parameter-sets/{set_id}", data={"values": {"C00039/1": 55.0,
                                                                                     "C00088": 12.5}}))
    return set_id


def test_a_download_with_a_failed_write_says_so_on_the_sets_page(page: Any, sets_server: str) -> None:
    set_id = _changed_set(page, sets_server)
    _ok(page.request.put(sets_server + SESSION + "/sdo-settings",
                         data={"timeout_s": 0.3, "retries": 1, "use_sdo2": False}))
    _ok(page.request.put(sets_server + SESSION + "/simulator/nodes/5/faults", data={"drop_downloads": 2}))

    page.goto(f"{sets_server}/parameter-sets?set={set_id}")
    page.locator("#set-detail").get_by_role("button", name="Preview changes").click()
    preview = page.locator("#download-area .preview")
    expect(preview).to_contain_text("2 of", timeout=WAIT_MS)
    preview.get_by_role("button", name="Download 2 changes").click()

    report = page.locator("#download-area .report")
    expect(report.locator(".report-head .status")).to_have_text("incomplete", timeout=WAIT_MS)
    expect(report.locator(".outcome")).to_have_text("1 written, 1 verified, 1 failed, 0 not written")
    bar = report.locator(".outcome-bar")
    assert bar.evaluate("el => el.value") < bar.evaluate("el => el.max")
    failed = report.locator("tr.line-failed")
    expect(failed).to_have_count(1)
    expect(failed).to_contain_text("C00039/1")
    assert failed.locator("td.wrap").inner_text().strip(), "the failed row says why"
    expect(page.locator("#set-downloads .status-incomplete")).to_have_count(1, timeout=WAIT_MS)
    page.locator("#download-area").scroll_into_view_if_needed()
    screenshot(page, "sets-download-incomplete")
