"""Line addressing in a real browser (Debian chromium) on the new-line plant: from the Plant page to the LSS page,
fastscan (confirmed in the page's dialog), assign node 20 to one device with store; it boots and appears on the
Plant page."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from drivebench.config import REPO_ROOT
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, screenshot, serve_app

NEW_LINE = REPO_ROOT / "plants" / "new-line.json"
TIMEOUT_MS = 30_000


@pytest.fixture
def line_server(app_db_url: str) -> Iterator[str]:
    with serve_app(create_app(plant_file=NEW_LINE, plant_bus=f"virtual:{fresh_channel()}@500000")) as url:
        yield url


def _confirm(page: Any) -> str:
    from playwright.sync_api import expect

    asked = page.locator("#moving-confirm")
    expect(asked).to_be_visible(timeout=TIMEOUT_MS)
    text = str(asked.inner_text())
    asked.get_by_role("button", name="Send it").click()
    return text


def test_fastscan_assign_store_and_the_node_boots_onto_the_plant_page(line_server: str, page: Any) -> None:
    from playwright.sync_api import expect

    page.goto(line_server + "/")
    page.locator("#lss-link-new-line").click()
    expect(page.locator("h1")).to_have_text("Line addressing (LSS)")
    page.get_by_role("button", name="Fastscan").click()
    asked = _confirm(page)
    assert "every node of the session" in asked and "reaches: all nodes on this bus" in asked
    assert "Every device on this bus hears it" in asked and "keeps the node alive" not in asked  # no drive is held
    rows = page.locator("#lss-devices tbody tr")
    expect(rows).to_have_count(4, timeout=TIMEOUT_MS)
    expect(page.locator("#lss-scan-result")).to_contain_text("4 devices found", timeout=TIMEOUT_MS)
    pump = page.locator("#lss-devices tbody tr[data-serial='0x00000BBB']")
    expect(pump.locator(".device")).to_contain_text("MICROMASTER")
    pump.locator(".node-id").fill("20")
    pump.get_by_role("button", name="Assign node ID").click()
    asked = _confirm(page)
    assert "node ID: 20" in asked and "store: yes" in asked
    expect(pump.locator(".steps")).to_contain_text("node 20 booted (boot-up telegram)", timeout=TIMEOUT_MS)
    expect(pump.locator(".steps")).to_contain_text("configuration stored in the device")
    screenshot(page, "lss-assigned")
    page.goto(line_server + "/")
    expect(page.locator("#link-new-line-20")).to_be_visible(timeout=TIMEOUT_MS)


def test_found_devices_are_told_by_their_answer_inquired_and_identified(line_server: str, page: Any) -> None:
    """Issue 32: a Lenze unit (its profiles carry no product code) shows vendor, numbers and the vendor's profiles
    instead of "unknown device"; Inquire selects one device and shows its identity; Identify remote slave answers
    in words. The read-only steps ask nothing."""
    from playwright.sync_api import expect

    page.goto(line_server + "/sessions/new-line/lss")
    page.get_by_role("button", name="Fastscan").click()
    _confirm(page)
    rows = page.locator("#lss-devices tbody tr")
    expect(rows).to_have_count(4, timeout=TIMEOUT_MS)
    conveyor = page.locator("#lss-devices tbody tr[data-serial='0x000003E9']")
    expect(conveyor.locator(".device")).to_contain_text("Lenze (vendor ID 0x0000003B), product code")
    expect(conveyor.locator(".device")).to_contain_text("carry no product code")
    expect(page.locator("#lss-devices")).not_to_contain_text("unknown device")
    pump = page.locator("#lss-devices tbody tr[data-serial='0x00000BBB']")
    pump.get_by_role("button", name="Inquire").click()
    expect(pump.locator(".steps")).to_contain_text("serial 0x00000BBB", timeout=TIMEOUT_MS)
    expect(pump.locator(".steps")).to_contain_text("It has no node ID (255).")
    form = page.locator("#lss-identify-form")
    form.locator("input[name=vendor]").fill("0x06000053")
    form.locator("input[name=product]").fill("2")
    form.get_by_role("button", name="Identify").click()
    expect(page.locator("#lss-identify-result")).to_contain_text("At least one device with vendor 0x06000053",
                                                                 timeout=TIMEOUT_MS)
    expect(page.locator("#moving-confirm")).not_to_be_visible()


def test_activate_bit_timing_from_the_page_moves_the_adapter_and_says_who_followed(line_server: str,
                                                                                    page: Any) -> None:
    """Issue 32 items 1 and 8: the page's *Activate bit timing* asks the confirmation that every device hears
    it, switches the devices configured to 250 kbit/s (the pump, assigned with that rate) and the session's
    adapter, and says in words who followed and who still answers at 500 kbit/s (the three not configured)."""
    from playwright.sync_api import expect

    page.goto(line_server + "/sessions/new-line/lss")
    page.get_by_role("button", name="Fastscan").click()
    _confirm(page)
    pump = page.locator("#lss-devices tbody tr[data-serial='0x00000BBB']")
    expect(pump).to_be_visible(timeout=TIMEOUT_MS)
    pump.locator(".node-id").fill("20")
    pump.locator(".bitrate").select_option("250000")
    pump.get_by_role("button", name="Assign node ID").click()
    _confirm(page)
    expect(pump.locator(".steps")).to_contain_text("node 20 booted (boot-up telegram)", timeout=TIMEOUT_MS)
    form = page.locator("#lss-activate-form")
    form.locator("select[name=bitrate]").select_option("250000")
    form.locator("input[name=switch_delay_ms]").fill("20")
    form.get_by_role("button", name="Activate bit timing").click()
    asked = _confirm(page)
    assert "Every device on this bus hears it" in asked and "bit rate: 250000" in asked, asked
    assert "reaches: all nodes on this bus" in asked
    result = page.locator("#lss-activate-result")
    expect(result).to_contain_text("This session's adapter now runs at 250 kbit/s.", timeout=TIMEOUT_MS)
    expect(result).to_contain_text("3 of 4 devices did not follow to 250 kbit/s")
    expect(result).to_contain_text("Followed: serial 0x00000BBB.")
    expect(result).to_contain_text("still answers at 500 kbit/s")
    screenshot(page, "lss-bit-rate-switched")
    page.goto(line_server + "/")
    expect(page.locator("body")).to_contain_text("virtual:", timeout=TIMEOUT_MS)
    expect(page.locator("body")).to_contain_text("@250000")
