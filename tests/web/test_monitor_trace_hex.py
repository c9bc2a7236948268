"""The Monitor trace reads an SDO transfer's value as the Parameters tab does (issue 30 item 5,
``device/profiles/number_base.py``): a COB-ID and a bit-coded word in hex with the data type's digits, an amount in
decimal; through the real app, the demo plant's simulated nodes on a virtual CAN bus and the monitor's HTTP API."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.confirming import confirmed

NODE = "/api/sessions/demo-plant/nodes"


def _summaries(api: TestClient, cob_id: str) -> list[str]:
    rows: list[dict[str, Any]] = api.get("/api/sessions/demo-plant/monitor/trace",
                                         params={"limit": 10000}).json()["rows"]
    return [row["summary"] for row in rows if row["cob_id"] == cob_id]


def test_cob_ids_and_words_read_in_hex_amounts_in_decimal(demo_api: TestClient) -> None:
    assert demo_api.get(f"{NODE}/5/parameters/0x1800.1").status_code == 200
    assert confirmed(demo_api, "PUT", f"{NODE}/5/parameters/C00088", json={"value": 12.5}).status_code == 200
    assert demo_api.get(f"{NODE}/12/parameters/C0135").status_code == 200
    answers, requests = _summaries(demo_api, "0x585"), _summaries(demo_api, "0x605")
    cob = next(text for text in answers if text.startswith("read response 0x1800sub1"))
    assert cob.endswith("= 0x00000185"), cob  # a COB-ID: hex, every digit of UNSIGNED32
    amount = next(text for text in requests if text.startswith("write 0x5FA7sub0"))
    assert amount.endswith("= 1250"), amount  # 12.50 A x 100: an amount, decimal
    word = next(text for text in _summaries(demo_api, "0x58C") if text.startswith("read response 0x5F78sub0"))
    assert word.endswith("= 0x0000") or word.endswith("= 0x0200"), word  # C0135, bit-coded: hex only
