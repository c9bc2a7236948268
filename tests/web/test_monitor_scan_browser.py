"""The Monitor page after a scan and a moved PDO (issue 28 item 7), in a browser on the uvicorn-served demo plant:
the scan's requests to node ids that never answered are one COB-ID row, in English and German, and a TPDO moved
through the PDO editor's API is its node's."""

from __future__ import annotations

from typing import Any

import can
import httpx

from drivebench.simulator.plant import Plant
from tests.confirming import confirmed
from tests.conftest import screenshot

DEMO = "/api/sessions/demo-plant"


def _scan_and_move(base_url: str, plant: Plant) -> None:
    with httpx.Client(base_url=base_url, timeout=60) as api:
        pdo = api.get(f"{DEMO}/nodes/7/pdos/tpdo/1").json()
        entries = [[entry["index"], entry["subindex"]] for entry in pdo["entries"]]
        moved = confirmed(api, "PUT", f"{DEMO}/nodes/7/pdos/tpdo/1", json={"cob_id": 0x2A7, "entries": entries})
        assert moved.status_code == 200 and moved.json()["ok"], moved.text
        assert api.post(f"{DEMO}/scan", json={"timeout_s": 0.3}).status_code == 200
    other = can.Bus(interface="virtual", channel=plant.spec.channel, receive_own_messages=False)
    try:  # another device on the bus sends on the moved TPDO's COB-ID (the simulated drive is pre-operational)
        for _ in range(3):
            other.send(can.Message(arbitration_id=0x2A7, data=b"\x01\x02", is_extended_id=False))
    finally:
        other.shutdown()


def _cob_row(page: Any, text: str) -> list[str]:
    row = page.locator("#cobs-body tr", has=page.locator("td.mono", has_text=text)).first
    return [cell.strip() for cell in row.locator("td").all_text_contents()]


def test_a_scan_is_one_cob_id_row_and_a_moved_tpdo_its_nodes(page: Any, demo_server: tuple[str, Plant]) -> None:
    base_url, plant = demo_server
    _scan_and_move(base_url, plant)
    page.goto(f"{base_url}/monitor/demo-plant")
    page.wait_for_selector("#live-state.live", timeout=20_000)
    page.wait_for_selector("#cobs-body td.mono >> text=0x2A7", timeout=20_000)
    page.wait_for_selector("#cobs-body td.mono >> text=0x601–0x67F", timeout=20_000)
    scan = _cob_row(page, "0x601–0x67F")
    assert scan[1] == "SDO requests to 121 node ids that never answered (a scan)" and scan[2] == "–", scan
    assert int(scan[3].replace(",", "")) >= 121, scan
    assert _cob_row(page, "0x2A7")[1:3] == ["TPDO1", "7"]
    requests = page.locator("#cobs-body td.mono", has_text="0x6").all_text_contents()
    assert requests == ["0x601–0x67F", "0x603", "0x605", "0x607", "0x60C", "0x645", "0x64C"], requests
    assert page.locator("#cobs-body tr").count() < 40
    box = "document.getElementById('cobs-body').closest('.scroll')"
    assert page.evaluate(f"{box}.scrollWidth <= {box}.clientWidth + 1"), "the scan row's words wrap: no sideways scroll"
    assert page.text_content("#cob-note") == ""  # every row shown: no "busiest n of m"
    screenshot(page, "monitor-scan-row")

    page.context.add_cookies([{"name": "drivebench_lang", "value": "de", "url": base_url}])
    page.goto(f"{base_url}/monitor/demo-plant")
    page.wait_for_selector("#cobs-body td.mono >> text=0x601–0x67F", timeout=20_000)
    assert _cob_row(page, "0x601–0x67F")[1] == "SDO-Anfragen an 121 Knotennummern, die nie antworteten (ein Scan)"
    screenshot(page, "monitor-scan-row-de")
