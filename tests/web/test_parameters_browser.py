"""The Node page's Parameters tab in a real browser: search, read, write, scaled values, errors beside the field.

Runs its own server on a Lenze-only plant (writes must not disturb the shared live server).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest

from drivebench.web.app import create_app
from tests.conftest import fresh_channel, screenshot, serve_app

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000
PLANT = {"name": "Browser plant", "nodes": [
    {"node_id": 5, "profile": "lenze-8400-motec-canopen", "name": "Conveyor", "values": {"C00061": 43},
     "heartbeat_ms": 500},
    {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib", "name": "Fan", "heartbeat_ms": 500},
]}
LAYOUT_PROBLEMS = """() => {
  const problems = [];
  if (document.documentElement.scrollWidth > window.innerWidth) problems.push("page scrolls sideways");
  for (const table of document.querySelectorAll("table")) {
    if (table.scrollWidth > table.parentElement.clientWidth + 1) problems.push("table wider than its card");
  }
  for (const cell of document.querySelectorAll("td, th, h1")) {
    if (cell.scrollWidth > cell.clientWidth + 1) problems.push("clipped: " + cell.textContent.trim().slice(0, 60));
  }
  return problems;
}"""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Any]]:
    plant = tmp_path_factory.mktemp("plant") / "plant.json"
    plant.write_text(json.dumps(PLANT), encoding="utf-8")
    app = create_app(plant_file=plant, plant_bus=f"virtual:{fresh_channel()}@500000", latency="2ms")
    with serve_app(app) as base_url:
        yield base_url, app


def _row(page: Any, ref: str) -> Any:
    return page.locator(f"tr[data-ref='{ref}']")


def _search(page: Any, text: str) -> None:
    page.fill("#param-q", text)
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=WAIT_MS)


def test_search_read_write_and_errors_beside_the_field(server: tuple[str, Any], page: Any) -> None:
    url, app = server
    page.goto(url + "/")
    page.locator("a[href='/sessions/browser-plant/nodes/5']").first.click()
    expect(page.locator("h1")).to_contain_text("Node 5", timeout=WAIT_MS)
    expect(page.locator("nav.tabs a.active")).to_have_text("Parameters")
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-node-page")

    _search(page, "rated motor current")
    row = _row(page, "C00088")
    row.get_by_role("button", name="Read").click()
    expect(_row(page, "C00088").locator("td.val")).to_contain_text("10.20 A", timeout=WAIT_MS)

    _row(page, "C00088").locator("input[name=value]").fill("12.5")
    _row(page, "C00088").get_by_role("button", name="Write").click()
    expect(_row(page, "C00088").locator("td.val")).to_contain_text("12.50 A", timeout=WAIT_MS)
    expect(_row(page, "C00088").locator("td.val")).to_contain_text("verified")
    screenshot(page, "parameters-written")

    # A device that keeps C00088 in 0.1 A steps: the read-back differs from what was written, and the row says so.
    store = app.state.drivebench.plants["browser-plant"].nodes[5].store
    store.add_write_hook(lambda index, sub, raw: store.set(index, sub, raw // 10 * 10, notify=False)
                         if (index, sub) == (0x5FA7, 0) else None)
    _row(page, "C00088").locator("input[name=value]").fill("12.34")
    _row(page, "C00088").get_by_role("button", name="Write").click()
    mismatch = _row(page, "C00088").locator(".verify.bad")
    expect(mismatch).to_contain_text("Wrote 12.34 A, the device reports 12.30 A", timeout=WAIT_MS)
    expect(_row(page, "C00088").locator("td.val .v")).to_have_text("12.30 A")
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-verify-mismatch")

    _search(page, "C00350")
    _row(page, "C00350").locator("input[name=value]").fill("100")
    _row(page, "C00350").get_by_role("button", name="Write").click()
    error = _row(page, "C00350").locator("td.edit .error")
    expect(error).to_contain_text("outside the allowed range 1 ... 63", timeout=WAIT_MS)
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-range-error")

    # A device whose range is narrower than its profile says: the SDO abort shows beside the field.
    slot = store.slot(0x5EA1, 0)
    slot.entry = slot.entry.model_copy(update={"max": 20})
    _row(page, "C00350").locator("input[name=value]").fill("30")
    _row(page, "C00350").get_by_role("button", name="Write").click()
    expect(_row(page, "C00350").locator("td.edit .error")).to_contain_text("0x06090030", timeout=WAIT_MS)
    screenshot(page, "parameters-sdo-abort")


def test_selection_list_reset_badge_and_read_all(server: tuple[str, Any], page: Any) -> None:
    url, _ = server
    page.goto(url + "/sessions/browser-plant/nodes/5")
    _search(page, "CAN baud rate")
    _row(page, "C00351").locator("select[name=value]").select_option("1")
    _row(page, "C00351").get_by_role("button", name="Write").click()
    expect(_row(page, "C00351").locator("td.val")).to_contain_text("1 = 250 kbit/s", timeout=WAIT_MS)
    expect(page.locator("#reset-badge")).to_contain_text("reset node required: C00351")

    page.fill("#param-q", "")
    page.get_by_role("button", name="Read all").click()
    expect(page.locator(".job-text")).to_contain_text("done", timeout=WAIT_MS)
    expect(_row(page, "C00061").locator("td.val")).to_contain_text("43 °C", timeout=WAIT_MS)
    screenshot(page, "parameters-read-all")
    assert page.evaluate(LAYOUT_PROBLEMS) == []

    page.once("dialog", lambda dialog: dialog.accept())
    page.get_by_role("button", name="Reset node").click()
    expect(page.locator("#command-result")).to_contain_text("resets", timeout=WAIT_MS)
    expect(page.locator("#reset-badge")).not_to_contain_text("C00351")


def test_read_all_cancel_keeps_values_then_group_read_and_sdo_settings(server: tuple[str, Any], page: Any) -> None:
    from drivebench.simulator.node import Latency

    url, app = server
    device = app.state.drivebench.plants["browser-plant"].nodes[12]
    device.latency = Latency(0.1)  # slow enough to cancel mid-way, even on a loaded machine
    try:
        page.goto(url + "/sessions/browser-plant/nodes/12")
        page.get_by_role("button", name="Read all").click()
        expect(page.locator(".job-text")).to_contain_text("ETA", timeout=WAIT_MS)
        expect(page.locator("tr.prow td.val .v").first).to_be_visible(timeout=WAIT_MS)  # values while it runs
        expect(page.locator(".job")).to_have_attribute("data-state", "running")
        screenshot(page, "parameters-read-all-running")
        page.locator(".job-cancel").click()
        expect(page.locator(".job-text")).to_contain_text("cancelled", timeout=WAIT_MS)
        rows = page.locator("tr.prow")
        expect(page.locator("tr.prow td.val .v").first).to_be_visible(timeout=WAIT_MS)
        kept = page.locator("tr.prow td.val .v").count()
        assert 0 < kept < rows.count()
    finally:
        device.latency = Latency(0.002)

    group_row = page.locator("tr.group-row").nth(1)
    group_name = group_row.locator(".group-name").inner_text()
    group_row.get_by_role("button", name="Read group").click()
    expect(page.locator(".job-text")).to_contain_text(f"Read group '{group_name}'", timeout=WAIT_MS)
    expect(page.locator(".job-text")).to_contain_text("done", timeout=WAIT_MS)

    page.locator("#sdo-settings summary").click()
    page.fill("#sdo-settings input[name=timeout_ms]", "200")
    page.fill("#sdo-settings input[name=retries]", "0")
    page.locator("#sdo-settings").get_by_role("button", name="Apply").click()
    expect(page.locator("#sdo-settings summary")).to_contain_text("SDO: 200 ms · 0 retries", timeout=WAIT_MS)
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-sdo-settings")
    page.locator("#sdo-settings input[name=timeout_ms]").fill("500")
    page.locator("#sdo-settings input[name=retries]").fill("1")
    page.locator("#sdo-settings").get_by_role("button", name="Apply").click()
    expect(page.locator("#sdo-settings summary")).to_contain_text("SDO: 500 ms · 1 retry", timeout=WAIT_MS)


def test_info_tab_reads_identity(server: tuple[str, Any], page: Any) -> None:
    url, _ = server
    page.goto(url + "/sessions/browser-plant/nodes/12")
    page.locator("nav.tabs a", has_text="Info").click()
    expect(page.locator("#identity-live")).to_contain_text("82S8212V_14000", timeout=WAIT_MS)
    expect(page).to_have_url(url + "/sessions/browser-plant/nodes/12?tab=info")
    screenshot(page, "node-info")



def test_string_read_by_block_upload(server: tuple[str, Any], page: Any) -> None:
    """Strings get a Block button where the device supports SDO block transfer (8400 motec, not the EMF2178IB)."""
    url, _ = server
    page.goto(url + "/sessions/browser-plant/nodes/5")
    _search(page, "C00099")
    row = _row(page, "C00099")
    row.get_by_role("button", name="Block").click()
    expect(_row(page, "C00099").locator("td.val .v")).to_have_text("01.00.00.00", timeout=WAIT_MS)
    expect(_row(page, "C00099").locator("td.val .via")).to_have_text("block")
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-block-upload")
    _row(page, "C00099").get_by_role("button", name="Read", exact=True).click()
    expect(_row(page, "C00099").locator("td.val .via")).to_have_count(0, timeout=WAIT_MS)
    expect(_row(page, "C00099").locator("td.val .v")).to_have_text("01.00.00.00")

    page.goto(url + "/sessions/browser-plant/nodes/12")
    _search(page, "C0200")
    expect(_row(page, "C0200").get_by_role("button", name="Read", exact=True)).to_be_visible()
    expect(_row(page, "C0200").get_by_role("button", name="Block")).to_have_count(0)


def test_header_nmt_badge_follows_nmt_commands(server: tuple[str, Any], page: Any) -> None:
    url, _ = server
    page.goto(url + "/sessions/browser-plant/nodes/12")
    badge = page.locator("#nmt-badge")
    expect(badge).to_have_text("Pre-operational", timeout=WAIT_MS)
    nmt = url + "/api/sessions/browser-plant/nodes/12/nmt"
    try:
        assert page.request.post(nmt, data={"command": "start", "confirm": 12, "confirm_values": {"NMT": "start"},
                                             **NO_BROWSER}).ok
        expect(badge).to_have_text("Operational", timeout=WAIT_MS)  # no reload: the badge polls its fragment
        expect(badge).to_have_class("nmt nmt-operational")
        screenshot(page, "parameters-nmt-badge-operational")
    finally:
        assert page.request.post(nmt, data={"command": "pre-operational"}).ok
    expect(badge).to_have_text("Pre-operational", timeout=WAIT_MS)


def test_parameter_set_selector_of_the_8200_vector(server: tuple[str, Any], page: Any) -> None:
    """EMF2178IB §10.2.1/§10.3: choose parameter set 2, the acceleration time row is C2012 (index 0x5823) shown as
    "C0012 · set 2"; writing it leaves set 1 as it was. The 8400 motec (one set) has no selector."""
    url, app = server
    page.goto(url + "/sessions/browser-plant/nodes/5")
    expect(page.locator("#param-rows")).to_be_visible(timeout=WAIT_MS)
    expect(page.locator("#param-set")).to_have_count(0)
    page.goto(url + "/sessions/browser-plant/nodes/12")
    page.locator("#param-set").select_option("2")
    expect(_row(page, "C2001")).to_be_visible(timeout=WAIT_MS)
    _search(page, "acceleration time")
    row = _row(page, "C2012")
    expect(row.locator("td.code")).to_have_text("C0012 · set 2")
    expect(row.locator("td.addr")).to_have_text("5823.0")
    row.locator("input[name=value]").fill("12.5")
    row.get_by_role("button", name="Write").click()
    expect(_row(page, "C2012").locator("td.val")).to_contain_text("verified", timeout=WAIT_MS)
    expect(_row(page, "C2012").locator("td.val .v")).to_have_text("12.5 s")
    store = app.state.drivebench.plants["browser-plant"].nodes[12].store
    assert store.get(0x5823, 0) == 125000 and store.get(0x5FF3, 0) != 125000  # FIX32; C0012 (set 1) unchanged
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "parameters-set-2")
    page.locator("#param-set").select_option("1")
    expect(_row(page, "C0012").locator("td.code")).to_have_text("C0012", timeout=WAIT_MS)


def test_read_shown_reads_a_group_in_one_request(server: tuple[str, Any], page: Any) -> None:
    url, _ = server
    page.goto(url + "/sessions/browser-plant/nodes/5")
    group_row = page.locator("tr.group-row").first
    refs = page.evaluate("""(header) => {
      const refs = [];
      for (let row = header.nextElementSibling; row && !row.matches(".group-row"); row = row.nextElementSibling)
        if (row.dataset.ref) refs.push(row.dataset.ref);
      return refs;
    }""", group_row.element_handle())
    assert len(refs) > 1
    sent: list[str] = []
    page.on("request", lambda request: sent.append(f"{request.method} {request.url}")
            if "/nodes/5/parameters" in request.url or request.url.endswith("/read") else None)
    group_row.get_by_role("button", name="Read shown").click()
    for ref in refs:
        expect(_row(page, ref).locator("td.val .v, td.val .read-error")).to_be_visible(timeout=WAIT_MS)
    assert sent == [f"POST {url}/api/sessions/browser-plant/nodes/5/parameters:read"]
    single = page.request.get(f"{url}/api/sessions/browser-plant/nodes/5/parameters/{refs[0]}").json()
    expect(_row(page, refs[0]).locator("td.val .v")).to_have_text(single["display"])  # as the single read shows it
    assert page.evaluate(LAYOUT_PROBLEMS) == []


def test_a_device_without_parameter_sets_reads_groups_without_console_errors(server: tuple[str, Any],
                                                                             page: Any) -> None:
    """Node 5 has one parameter set: the read buttons include no set selector that is not there (htmx would log
    an error for every click)."""
    from tests.web.test_ux_browser import Watch

    url, _app = server
    watch = Watch(page, url)
    page.goto(url + "/sessions/browser-plant/nodes/5")
    expect(page.locator("#param-set")).to_have_count(0)
    page.locator("tr.group-row").nth(1).get_by_role("button", name="Read group").click()
    expect(page.locator(".job-text")).to_contain_text("done", timeout=WAIT_MS)
    page.get_by_role("button", name="Read all").click()
    expect(page.locator(".job-text")).to_contain_text("done", timeout=WAIT_MS)
    assert watch.problems == []


def test_back_to_the_tab_of_a_running_read_all_shows_it_finish(tmp_path: Any, page: Any) -> None:
    """Back from another tab restores htmx's snapshot of the page: a read job's box in it follows the job again
    (it stood still at the count of the moment the tab was left)."""
    from tests.web.test_ux_browser import Watch

    plant = tmp_path / "plant.json"
    plant.write_text(json.dumps(PLANT), encoding="utf-8")
    app = create_app(plant_file=plant, plant_bus=f"virtual:{fresh_channel()}@500000", latency="15ms")
    with serve_app(app) as url:
        watch = Watch(page, url)
        page.goto(url + "/sessions/browser-plant/nodes/5")
        page.get_by_role("button", name="Read all").click()
        expect(page.locator(".job-text")).to_contain_text("/s", timeout=WAIT_MS)  # running, the socket reports
        page.click("nav.tabs a[data-tab=info]")
        expect(page.locator("#node-tab")).to_have_attribute("data-tab", "info", timeout=WAIT_MS)
        page.go_back()
        expect(page.locator(".job-text")).to_contain_text("done", timeout=60_000)
        screenshot(page, "parameters-read-all-after-back")
        assert watch.problems == []


def test_a_row_read_sends_only_its_own_fields(server: tuple[str, Any], page: Any) -> None:
    """The rows sit in the table body that re-reads itself with the filter: their requests do not carry the
    filter's fields (htmx 2 passes an ancestor's hx-include down unless told not to)."""
    url, _app = server
    page.goto(url + "/sessions/browser-plant/nodes/5")
    _search(page, "C00061")
    with page.expect_request(lambda request: request.url.endswith("/parameters/C00061/read")) as sent:
        _row(page, "C00061").get_by_role("button", name="Read", exact=True).click()
    assert sent.value.post_data in (None, ""), sent.value.post_data
    expect(_row(page, "C00061").locator("td.val .v")).to_be_visible(timeout=WAIT_MS)


def test_a_search_typed_while_the_page_loads_is_not_lost(server: tuple[str, Any], page: Any) -> None:
    """The page's scripts held back on the wire: the user types into the search before htmx has set up the
    filter (a slow network or a busy machine); once the page is ready the table shows what was typed."""
    url, _app = server
    held: list[Any] = []
    page.route("**/static/app.js", lambda route: held.append(route))
    page.goto(url + "/sessions/browser-plant/nodes/5", wait_until="commit")
    page.fill("#param-q", "C00061")
    expect(page.locator("#param-rows")).not_to_have_attribute("data-count", "1")  # nothing can search yet
    assert len(held) == 1
    held[0].continue_()
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=WAIT_MS)
    expect(_row(page, "C00061")).to_be_visible()
