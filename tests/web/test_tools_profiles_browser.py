"""The Tools page in a real browser plans a line with node 7's generic CiA 402 servo and an EDS uploaded through the
real API (issue 30 item 7): both in the planner's device list, their COB-IDs and bit rates checked from their
profiles, the cable checked for the line; the page says which devices have no DIP calculator and which are on no CAN
line. At 1440 and 1024 px, on a server of its own (no bus, temporary database and upload directory)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import requests

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.web.app import create_app
from tests.conftest import screenshot, serve_app
from tests.web.test_tools_browser import LAYOUT_PROBLEMS

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000
EDS = Path(__file__).resolve().parents[1] / "data" / "eds" / "cia402_servo.eds"


@pytest.fixture(scope="module")
def server_with_eds(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, str]]:
    """The app in uvicorn with the EDS uploaded over POST /api/profiles; yields its URL and the profile id."""
    work = tmp_path_factory.mktemp("tools-profiles")
    url = f"sqlite:///{work / 'drivebench.db'}"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", url)
        patch.setattr(settings, "user_profiles_dir", work / "uploads")
        with serve_app(create_app()) as base_url:
            response = requests.post(f"{base_url}/api/profiles", files={"file": ("em-servo.eds", EDS.read_bytes())},
                                     timeout=60)
            assert response.status_code == 201, response.text
            yield base_url, response.json()["id"]
    database.dispose(url)


def plan_row(page: Any, row: int, device: str, node_id: int) -> None:
    page.locator(f'#planner select[name="device_{row}"]').select_option(device)  # re-renders the planner
    # the planner re-rendered for the new device: its PDOs are channels of their own (the seeds' PDO1 ... are not)
    expect(page.locator(f'#planner .plan-row[data-row="{row}"] .channels')).to_contain_text("RPDO1", timeout=WAIT_MS)
    page.locator(f'#planner input[name="node_id_{row}"]').fill(str(node_id))
    page.locator(f'#planner input[name="node_id_{row}"]').blur()


@pytest.mark.parametrize("width", [1440, 1024])
def test_plan_node_7_and_an_uploaded_eds_on_the_tools_page(page: Any, server_with_eds: tuple[str, str],
                                                           width: int) -> None:
    base_url, eds_id = server_with_eds
    page.set_viewport_size({"width": width, "height": 900})
    page.goto(f"{base_url}/tools")
    expect(page.locator("#dip-none")).to_contain_text("No DIP-switch calculator for", timeout=WAIT_MS)
    expect(page.locator("#dip-none")).to_contain_text("Generic CiA 402 servo")
    expect(page.locator("#dip-none")).to_contain_text("EM-Servo 400")
    expect(page.locator("#plan-not-on-can")).to_contain_text("EtherCAT has no node id, bit rate or COB-ID plan")

    plan_row(page, 0, "generic-cia402-servo", 7)
    plan_row(page, 1, eds_id, 8)
    expect(page.locator('#planner .plan-row[data-row="0"] .channels')).to_contain_text("TPDO3")
    page.locator('#planner input[name="cable_length_m"]').fill("80")
    page.locator('#planner input[name="cable_length_m"]').blur()
    expect(page.locator("#findings .finding.none")).to_be_visible(timeout=WAIT_MS)
    expect(page.locator("#plan-results")).to_contain_text("Cable: 0 repeater(s), max. 113 m at 500 kbit/s",
                                                          timeout=WAIT_MS)
    page.locator("#plan-results details.cob-plan summary").click()
    cob_rows = page.locator("#plan-results details.cob-plan tbody tr")
    for hex_id, service in (("0x187", "TPDO1"), ("0x407", "RPDO3"), ("0x288", "TPDO2"), ("0x588", "SDO1 tx")):
        expect(cob_rows.filter(has_text=hex_id)).to_contain_text(service, timeout=WAIT_MS)

    page.locator('#planner select[name="baud_kbit_1"]').select_option("800")  # the EDS: BaudRate_800=0
    unsupported = page.locator('#findings .finding[data-kind="unsupported_baud"]')
    expect(unsupported).to_contain_text("EM-Servo 400 does not support 800 kbit/s (125, 250, 500, 1000)",
                                        timeout=WAIT_MS)
    page.locator("#planner").scroll_into_view_if_needed()
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, f"tools-planner-profiles-{width}")
