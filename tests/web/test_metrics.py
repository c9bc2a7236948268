"""Prometheus metrics at /metrics (issue 33): requests by route template, SDO failures, sessions, bus frames and
jobs, read through the real app; only with the metrics token or the engineer role."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families

from drivebench.config import settings
from tests.web.test_access import app_client, own_db, users  # noqa: F401 (fixtures)

SESSION, SERVO = "demo-plant", 7


def _samples(text: str) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    return {(sample.name, tuple(sorted(sample.labels.items()))): sample.value
            for family in text_string_to_metric_families(text) for sample in family.samples}


def _value(text: str, name: str, **labels: str) -> float:
    return _samples(text).get((name, tuple(sorted(labels.items()))), 0.0)


def test_metrics_count_requests_by_route_sdo_aborts_sessions_and_frames(demo_api: TestClient) -> None:
    read = f"/api/sessions/{SESSION}/nodes/{SERVO}/parameters/0x1008"
    before = demo_api.get("/metrics")
    assert before.status_code == 200 and before.headers["content-type"].startswith("text/plain")
    aborts_before = _value(before.text, "drivebench_sdo_failures_total", kind="abort")
    assert demo_api.get(read).status_code == 200
    assert demo_api.put(f"/api/sessions/{SESSION}/simulator/nodes/{SERVO}/faults",
                        json={"abort_code": "0x06020000", "abort_index": 0x1008}).status_code == 200
    refused = demo_api.get(read)
    assert refused.status_code >= 400
    after = demo_api.get("/metrics").text
    route = "/api/sessions/{session_id}/nodes/{node_id}/parameters/{ref:path}"
    assert _value(after, "drivebench_http_requests_total", method="GET", route=route, status="200") >= 1
    assert _value(after, "drivebench_http_requests_total", method="GET", route=route,
                  status=str(refused.status_code)) >= 1
    assert _value(after, "drivebench_http_request_duration_seconds_count", method="GET", route=route) >= 2
    assert _value(after, "drivebench_sdo_failures_total", kind="abort") >= aborts_before + 1
    assert _value(after, "drivebench_sessions") == len(demo_api.get("/api/sessions").json()) >= 1
    assert _value(after, "drivebench_bus_frames_total", session=SESSION) > 0, "the SDO frames went over the bus"
    assert not re.search(r'route="/api/sessions/demo-plant', after), "paths with ids would make labels unbounded"


@pytest.mark.usefixtures("users")
def test_metrics_need_the_engineer_role_or_the_metrics_token(app_client: TestClient, tmp_path: Path,  # noqa: F811
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    token_file = tmp_path / "metrics_token"
    token_file.write_text("scraper-secret-1234\n")
    monkeypatch.setattr(settings, "metrics_token_file", token_file)
    anonymous = app_client.get("/metrics")
    assert anonymous.status_code == 401
    assert app_client.get("/metrics", headers={"Authorization": "Bearer wrong"}).status_code == 401
    scraper = app_client.get("/metrics", headers={"Authorization": "Bearer scraper-secret-1234"})
    assert scraper.status_code == 200 and "drivebench_sessions" in scraper.text
    # the token reads metrics and nothing else
    assert app_client.get(f"/api/sessions/{SESSION}/nodes", headers={
        "Authorization": "Bearer scraper-secret-1234"}).status_code == 401
    viewer = app_client.post("/api/auth/login", json={"name": "vera", "password": "viewer password"})
    assert viewer.status_code == 200
    refused = app_client.get("/metrics")
    detail = refused.json()["detail"]
    assert refused.status_code == 403 and "engineer" in detail and "metrics" in detail
    app_client.post("/api/auth/logout", headers={"X-CSRF-Token": viewer.json()["csrf_token"]})
    assert app_client.post("/api/auth/login", json={"name": "eve", "password": "engineer password"}).status_code == 200
    assert app_client.get("/metrics").status_code == 200
