"""The small ones of issue 28 item 15, each through the real path: the share-link cookie is Secure over https; the
access log of `drivebench serve --log-level info` holds no whole token; /docs (scripts from a CDN) is off unless
asked for; a new SQLite file is 0600; a 422 does not echo what was submitted (a password)."""

from __future__ import annotations

import contextlib
import stat
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.services.storage import database
from drivebench.web.app import create_app
from tests.conftest import _free_port
from tests.transport.test_multiprocess import CliProcess
from tests.web.test_access import own_db

__all__ = ["own_db"]  # the fixture shared with test_access


def test_the_share_link_cookie_is_secure_over_https(own_db: str) -> None:
    with TestClient(create_app(), base_url="https://127.0.0.1") as client:
        link = client.post("/api/share-links", json={"ttl_minutes": 10, "label": "remote"})
        assert link.status_code == 201, link.text
        opened = client.get(f"/remote/{link.json()['token']}", follow_redirects=False)
        assert opened.status_code == 200, opened.text[:300]
        cookie = opened.headers["set-cookie"]
        assert cookie.startswith("drivebench_viewer=") and "Secure" in cookie and "HttpOnly" in cookie, cookie
    with TestClient(create_app(), base_url="http://127.0.0.1") as client:  # plain http (on this machine): not
        link = client.post("/api/share-links", json={"ttl_minutes": 10, "label": "remote"})
        assert "Secure" not in client.get(f"/remote/{link.json()['token']}").headers["set-cookie"]


@contextlib.contextmanager
def _serving(tmp_path: Path, *options: str) -> Iterator[tuple[CliProcess, str]]:
    port = _free_port()
    server = CliProcess("serve", "--port", str(port), *options,
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}",
                             "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "secret_key")})
    try:
        server.wait_for_line(r"DriveBench on http://")
        yield server, f"http://127.0.0.1:{port}"
    finally:
        server.stop()


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_the_access_log_holds_no_whole_token(tmp_path: Path) -> None:
    with _serving(tmp_path, "--log-level", "info") as (server, url):
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{url}/api/health", timeout=10).status_code == 200:
                    break
            time.sleep(0.2)
        token = httpx.post(f"{url}/api/share-links", json={"ttl_minutes": 10, "label": "log"},
                           timeout=30).json()["token"]
        assert httpx.get(f"{url}/remote/{token}", timeout=30).status_code == 200
        assert httpx.get(f"{url}/api/sessions", params={"link": token}, timeout=30).status_code == 200
        server.wait_for_line(r"GET /api/sessions\?link=")
        server.stop()
    log = "".join(server.output)
    assert token not in log, log[-2000:]
    assert f"GET /remote/{token[:10]}…" in log, log[-2000:]  # the hint the Remote page shows


def test_the_docs_pages_are_off_in_production(own_db: str) -> None:
    with TestClient(create_app()) as client:
        assert client.get("/docs").status_code == 404
        assert client.get("/redoc").status_code == 404
        assert client.get("/openapi.json").status_code == 200


def test_a_new_sqlite_file_is_readable_by_its_owner_only(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'new' / 'drivebench.db'}"
    database.upgrade_to_head(url)
    try:
        assert stat.S_IMODE((tmp_path / "new" / "drivebench.db").stat().st_mode) == 0o600
    finally:
        database.dispose(url)


@pytest.mark.parametrize(("path", "body"), [
    ("/api/users", {"name": "otto", "password": "sEcr3t", "role": "engineer"}),  # too short
    ("/api/auth/login", {"name": "", "password": "the sEcr3t password"}),
    ("/api/users/otto/password", {"password": "sEcr3t"}),
])
def test_a_422_does_not_echo_a_password(own_db: str, path: str, body: dict[str, str]) -> None:
    with TestClient(create_app()) as client:
        answer = client.request("PUT" if path.endswith("password") else "POST", path, json=body)
    assert answer.status_code == 422, answer.text
    assert "sEcr3t" not in answer.text
    assert answer.json()["errors"] and answer.json()["detail"]  # it still says what is wrong, and where
