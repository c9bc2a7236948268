"""The Tools screen in a real browser: click the drawn 8400 motec switches, type an address and watch the switches
move, switch family, and let the planner find a duplicate node id. Runs on a server of its own (no bus, temporary
database), so it does not depend on the demo plant's profiles."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.web.app import create_app
from tests.conftest import screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000
ADDRESS_SWITCHES = ("64", "32", "16", "8", "4", "2", "1")

LAYOUT_PROBLEMS = """() => {
  const problems = [];
  if (document.documentElement.scrollWidth > window.innerWidth) problems.push("page scrolls sideways");
  for (const table of document.querySelectorAll("table")) {
    if (table.offsetParent && table.scrollWidth > table.parentElement.clientWidth + 1)
      problems.push("table wider than its box: " + (table.id || table.className));
  }
  return problems;
}"""


@pytest.fixture(scope="module")
def tools_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    url = f"sqlite:///{tmp_path_factory.mktemp('tools-db') / 'drivebench.db'}"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", url)
        with serve_app(create_app()) as base_url:
            yield base_url
    database.dispose(url)


def switch(page: Any, label: str) -> Any:
    return page.locator(f'#dip [data-switch="{label}"]')


def test_click_8400_switches_shows_address_baud_and_cob_ids(page: Any, tools_server: str) -> None:
    page.goto(f"{tools_server}/tools")
    expect(page.locator("#dip-node-value")).to_have_text("1", timeout=WAIT_MS)  # all OFF: C00350 Lenze setting
    expect(page.locator("#dip-result")).to_contain_text("from C00350")
    for label in ("16", "4", "2", "1"):  # the manual's example: 16 + 4 + 2 + 1 = 23
        switch(page, label).click()
        expect(switch(page, label)).to_have_attribute("aria-checked", "true", timeout=WAIT_MS)
    expect(page.locator("#dip-node-value")).to_have_text("23", timeout=WAIT_MS)
    expect(page.locator('#cob-table tr[data-service="TPDO1"]')).to_contain_text("0x197")
    expect(page.locator('#cob-table tr[data-service="TPDO1"]')).to_contain_text("407")
    switch(page, "a").click()  # c b a = OFF OFF ON: 250 kbit/s (§6.3.1)
    expect(page.locator("#dip-baud-value")).to_have_text("250 kbit/s", timeout=WAIT_MS)
    expect(page.locator("#dip-node-id")).to_have_value("23")
    page.locator('input[name="pdo_ids"][value="lenze"]').check()
    expect(page.locator('#cob-table tr[data-service="RPDO2"]')).to_contain_text(f"0x{0x281 + 23:03X}",
                                                                                  timeout=WAIT_MS)
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "tools-dip-8400-node-23")

    switch(page, "64").click()
    expect(page.locator("#dip-node-value")).to_have_text("63", timeout=WAIT_MS)
    expect(page.locator("#dip-result")).to_contain_text("node address 63 is always used")


def test_typing_an_address_moves_the_switches(page: Any, tools_server: str) -> None:
    page.goto(f"{tools_server}/tools")
    page.locator("#dip-node-id").fill("42")
    for label in ADDRESS_SWITCHES:
        expect(switch(page, label)).to_have_attribute("aria-checked", "true" if label in ("32", "8", "2") else "false",
                                                      timeout=WAIT_MS)
    page.locator("#dip-baud").select_option("125")
    expect(switch(page, "b")).to_have_attribute("aria-checked", "true", timeout=WAIT_MS)
    expect(switch(page, "a")).to_have_attribute("aria-checked", "false")
    expect(switch(page, "c")).to_have_attribute("aria-checked", "false")
    expect(page.locator("#dip-node-value")).to_have_text("42")
    expect(page.locator('#cob-table tr[data-service="SDO1 tx"]')).to_contain_text("0x5AA")
    screenshot(page, "tools-dip-8400-typed-42")

    page.locator("#dip-node-id").fill("64")  # the 8400 motec cannot use 64: error beside the field, switches stay
    expect(page.locator("#dip .error")).to_contain_text("outside 1 … 63", timeout=WAIT_MS)
    expect(switch(page, "32")).to_have_attribute("aria-checked", "true")


def test_other_families(page: Any, tools_server: str) -> None:
    page.goto(f"{tools_server}/tools")
    page.locator('[data-family="lenze-emf2178ib"]').click()
    expect(page.locator("#dip .dip-switch")).to_have_count(10, timeout=WAIT_MS)
    for label in ("S3", "S5", "S6", "S7"):  # EMF2178IB manual §6.3 example: 16 + 4 + 2 + 1 = 23
        switch(page, label).click()
        expect(switch(page, label)).to_have_attribute("aria-checked", "true", timeout=WAIT_MS)
    expect(page.locator("#dip-node-value")).to_have_text("23")
    screenshot(page, "tools-dip-emf2178ib")
    page.locator('[data-family="siemens-mm4"]').click()
    expect(page.locator("#dip .dip-switch")).to_have_count(0, timeout=WAIT_MS)
    expect(page.locator("#dip")).to_contain_text("P0918")
    page.locator("#dip-node-id").fill("4")
    page.locator("#dip-baud").select_option("250")
    expect(page.locator("#dip .alt-table")).to_contain_text("P2041.04", timeout=WAIT_MS)
    expect(page.locator("#dip-node-value")).to_have_text("4")
    screenshot(page, "tools-dip-micromaster")


def test_planner_finds_a_duplicate_node_id_and_saves(page: Any, tools_server: str, tmp_path: Path) -> None:
    page.goto(f"{tools_server}/tools")
    expect(page.locator("#findings .finding.none")).to_be_visible(timeout=WAIT_MS)
    page.locator('input[name="node_id_1"]').fill("1")
    page.locator('input[name="node_id_1"]').blur()
    duplicate = page.locator('#findings .finding[data-kind="duplicate_node_id"]')
    expect(duplicate).to_contain_text("Node id 1 is planned 2 times", timeout=WAIT_MS)
    page.locator("#planner-form button", has_text="Add node").click()
    expect(page.locator("#planner .plan-row")).to_have_count(3, timeout=WAIT_MS)
    page.locator('#planner select[name="baud_kbit_2"]').select_option("250")
    expect(page.locator('#findings .finding[data-kind="mixed_baud"]')).to_be_visible(timeout=WAIT_MS)
    page.locator("#planner-form button", has_text="Save").click()
    expect(page.locator("#planner .saved-table tr[data-saved]")).to_have_count(1, timeout=WAIT_MS)

    bad = tmp_path / "broken.json"
    bad.write_text("{ not a plan")
    page.locator('#planner input[name="plan_file"]').set_input_files(str(bad))
    expect(page.locator("#planner-errors .error")).to_contain_text("Not a network plan", timeout=WAIT_MS)
    expect(page.locator("#planner .plan-row")).to_have_count(3)  # nothing lost
    page.locator("#planner").scroll_into_view_if_needed()
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "tools-planner-duplicate")


def test_export_json_downloads_the_plan_being_edited_and_it_imports_again(page: Any, tools_server: str,
                                                                          tmp_path: Path) -> None:
    page.goto(f"{tools_server}/tools")
    expect(page.locator("#findings .finding.none")).to_be_visible(timeout=WAIT_MS)
    page.locator('#planner input[name="plan_name"]').fill("Hall 2 / line A")
    page.locator('input[name="node_id_1"]').fill("17")
    with page.expect_download(timeout=WAIT_MS) as download_info:
        page.locator("#planner-form button", has_text="Export JSON").click()
    download = download_info.value
    assert download.suggested_filename == "Hall-2---line-A.json"
    saved = tmp_path / download.suggested_filename
    download.save_as(saved)
    exported = json.loads(saved.read_text())
    assert exported["name"] == "Hall 2 / line A"
    assert [n["node_id"] for n in exported["nodes"]] == [1, 17]

    page.reload()  # a fresh page starts with the default plan again
    expect(page.locator('input[name="node_id_1"]')).to_have_value("2", timeout=WAIT_MS)
    page.locator('#planner input[name="plan_file"]').set_input_files(str(saved))
    expect(page.locator('input[name="node_id_1"]')).to_have_value("17", timeout=WAIT_MS)
    expect(page.locator('#planner input[name="plan_name"]')).to_have_value("Hall 2 / line A")
