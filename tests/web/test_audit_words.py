"""The audit log in the reader's language (issue 28 item 10): a German reader sees the origin 'parameters' (and
the stored details DriveBench writes) in German, as the result column already is."""

from __future__ import annotations

from fastapi.testclient import TestClient

from tests.confirming import confirmed

GERMAN = {"Accept-Language": "de"}


def test_audit_origin_is_german_for_a_german_reader(demo_api: TestClient) -> None:
    written = confirmed(demo_api, "PUT", "/api/sessions/demo-plant/nodes/5/parameters/C00088",
                        json={"value": "10.20 A"})
    assert written.status_code == 200, written.text
    rows = demo_api.get("/parameter-sets/audit/rows", headers=GERMAN).text
    assert "C00088" in rows
    assert "<td>parameters</td>" not in rows
    assert "<td>Parameter</td>" in rows or "<td>Parameterliste</td>" in rows


def test_every_origin_the_tool_writes_is_german_for_a_german_reader(demo_api: TestClient) -> None:
    producer = demo_api.put("/api/sessions/demo-plant/nodes/5/heartbeat/producer", json={"time_ms": 200})
    assert producer.status_code == 200, producer.text
    rows = demo_api.get("/parameter-sets/audit/rows", headers=GERMAN).text
    assert "0x1017" in rows
    assert "<td>diagnostics</td>" not in rows
    assert "<td>Diagnose</td>" in rows
