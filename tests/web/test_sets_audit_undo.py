"""The Sets page's audit log offers undo like the node's Parameters tab (issue 30 item 5), through the real app on
the demo plant: each record an Undo button (or, disabled, why not), the old value written back through the checked
write and read back, a moving old value asked with the confirmation first."""

from __future__ import annotations

import re
from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed

NODE = "/api/sessions/demo-plant/nodes"


def _audit(api: TestClient, node: int) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = api.get("/api/audit", params={"node_id": node}).json()
    return rows


def _row(page: str, record: int) -> str:
    found = re.search(rf'<tr data-record="{record}">.*?</tr>', page, re.S)
    assert found, f"record {record} is not in the audit log"
    return found.group(0)


def test_the_sets_page_audit_log_undoes_a_write(demo_api: TestClient) -> None:
    assert demo_api.get(f"{NODE}/5/parameters/C00088").json()["display"] == "10.20 A"
    assert confirmed(demo_api, "PUT", f"{NODE}/5/parameters/C00088", json={"value": 12.5}).status_code == 200
    assert confirmed(demo_api, "PUT", f"{NODE}/5/parameters/C00011", json={"value": 1400}).status_code == 200
    unread, written = _audit(demo_api, 5)[:2]  # C00011 was never read: its record has no old value
    page = demo_api.get("/parameter-sets").text
    assert f'hx-post="/parameter-sets/audit/{written["id"]}/undo?q="' in _row(page, written["id"])
    refused = _row(page, unread["id"])
    assert "disabled" in refused and "has no old value" in refused and "hx-post" not in refused

    answer = demo_api.post(f"/parameter-sets/audit/{written['id']}/undo", params={"q": "C000"})
    assert answer.status_code == 200, answer.text
    assert f"Record {written['id']} undone: C00088 = 10.20 A written back" in answer.text
    assert "verified" in answer.text and 'value="C000"' in answer.text  # the filter stays
    assert demo_api.get(f"{NODE}/5/parameters/C00088").json()["display"] == "10.20 A"
    newest = _audit(demo_api, 5)[0]
    assert (newest["origin"], newest["new_value"], newest["result"]) == (f"undo {written['id']}", "10.20 A",
                                                                          "written")
    assert f'<tr data-record="{newest["id"]}">' in answer.text


def test_a_moving_undo_on_the_sets_page_asks_first(demo_api: TestClient) -> None:
    old = demo_api.get(f"{NODE}/7/parameters/0x6060").json()
    assert confirmed(demo_api, "PUT", f"{NODE}/7/parameters/0x6060",
                     json={"value": 3 if old["raw"] != 3 else 1}).status_code == 200
    record = _audit(demo_api, 7)[0]
    url = f"/parameter-sets/audit/{record['id']}/undo"
    asked = demo_api.post(url, headers={"HX-Request": "true"})
    assert asked.status_code == 428, asked.text
    assert 'data-confirm-node="7"' in asked.text
    assert demo_api.get(f"{NODE}/7/parameters/0x6060").json()["raw"] != old["raw"], "nothing was written"
    values = re.search(r"data-confirm-values=\"([^\"]*)\"", asked.text)
    assert values is not None
    confirmed_values = values.group(1).replace("&#34;", '"').replace("&quot;", '"')
    answer = demo_api.post(url, data={"confirm": "7", "confirm_values": confirmed_values})
    assert answer.status_code == 200, answer.text
    assert demo_api.get(f"{NODE}/7/parameters/0x6060").json()["raw"] == old["raw"]
