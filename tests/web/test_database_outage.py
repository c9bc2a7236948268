"""A database outage while the server runs (issue 33): /api/health still answers and says the database is
unreachable and why; sign-in answers 503 problem+json in words instead of a 500. The outage is a TCP relay in front
of the suite's PostgreSQL cluster, cut while the server runs (the cluster itself serves other tests)."""

from __future__ import annotations

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.web.app import create_app
from tests.conftest import serve_app, wait_for_value
from tests.pg_cluster import PostgresCluster
from tests.tcp_relay import TcpRelay

PASSWORD = "a long password"


@pytest.mark.postgresql
def test_health_reports_an_unreachable_database_and_sign_in_answers_503_in_words(
        postgres: PostgresCluster, monkeypatch: pytest.MonkeyPatch) -> None:
    direct = postgres.new_database()
    relay = TcpRelay(postgres.port)
    url = direct.replace(f"127.0.0.1:{postgres.port}", f"127.0.0.1:{relay.port}")
    monkeypatch.setattr(settings, "database_url", url)
    try:
        database.upgrade_to_head(url)
        accounts.create_first_admin("root", PASSWORD)
        with serve_app(create_app()) as base:
            first = httpx.get(f"{base}/api/health", timeout=30).json()
            assert first["status"] == "ok" and first["database"] == "ok"
            relay.cut()

            def unreachable() -> dict[str, object] | None:
                answer = httpx.get(f"{base}/api/health", timeout=30)
                assert answer.status_code == 200  # the server itself still serves: only the database is down
                body = answer.json()
                return body if body["database"] == "unreachable" else None

            body = wait_for_value(unreachable, seconds=30, what="health reporting the database unreachable")
            assert body["status"] == "ok"
            assert f"127.0.0.1:{relay.port}" in str(body["database_reason"])
            assert "refused" in str(body["database_reason"])

            signed_in = httpx.post(f"{base}/api/auth/login", json={"name": "root", "password": PASSWORD},
                                   timeout=30)
            assert signed_in.status_code == 503
            assert signed_in.headers["content-type"] == "application/problem+json"
            problem = signed_in.json()
            assert problem["title"] == "Database unreachable"
            assert f"127.0.0.1:{relay.port}" in problem["detail"] and "refused" in problem["detail"]
            assert "PostgreSQL" in problem["hint"]
            assert PASSWORD not in signed_in.text

            other = httpx.get(f"{base}/api/sessions", timeout=30)  # the user list lives in the database too
            assert other.status_code == 503 and other.json()["title"] == "Database unreachable"
    finally:
        relay.cut()
        database.dispose(url)
        postgres.drop_database(direct)


def test_health_reports_the_database_ok_on_sqlite(app_db_url: str) -> None:
    with TestClient(create_app()) as client:
        body = client.get("/api/health").json()
    assert body["status"] == "ok" and body["database"] == "ok" and body["database_reason"] is None
