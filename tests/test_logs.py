"""The server's log as plant IT reads it (issue 33): JSON lines with time, level, logger and request id on request,
an access line per request, failed sign-ins logged with who and from where but never the password, and the request
id a proxy sent echoed in the answer and in every record of that request."""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

import httpx
import pytest

from tests.conftest import _free_port, wait_until
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = pytest.mark.slow  # a server process of its own

ADMIN_PASSWORD = "first start password"
WRONG_PASSWORD = "not-the-password-42"


def _records(output: list[str]) -> list[dict[str, object]]:
    records = []
    for line in output:
        if line.startswith("{"):
            records.append(json.loads(line))
    return records


def test_json_log_names_each_request_and_failed_sign_ins_without_the_password(tmp_path: Path) -> None:
    secret = tmp_path / "admin_password"
    secret.write_text(ADMIN_PASSWORD + "\n")
    port = _free_port()
    env = {"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'drivebench.db'}",
           "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "secret_key"), "DRIVEBENCH_ADMIN_USER": "plantadmin",
           "DRIVEBENCH_ADMIN_PASSWORD_FILE": str(secret), "DRIVEBENCH_LOG_FORMAT": "json",
           "DRIVEBENCH_LOG_LEVEL": "info"}
    server = CliProcess("serve", "--port", str(port), env=env)
    base = f"http://127.0.0.1:{port}"
    try:
        server.wait_for_line(r"DriveBench on http://127\.0\.0\.1:")
        assert wait_until(lambda: _answers(base), START_TIMEOUT_S)
        health = httpx.get(base + "/api/health", headers={"X-Request-ID": "proxy-trace-42"}, timeout=10)
        assert health.headers["X-Request-ID"] == "proxy-trace-42"
        failed = httpx.post(base + "/api/auth/login", json={"name": "plantadmin", "password": WRONG_PASSWORD},
                            timeout=10)
        assert failed.status_code == 401
        made_up = failed.headers["X-Request-ID"]
        assert made_up and made_up != "proxy-trace-42"
        odd = httpx.get(base + "/api/health", headers={"X-Request-ID": "bad id\twith spaces"}, timeout=10)
        assert odd.headers["X-Request-ID"] != "bad id\twith spaces", "a request id is letters, digits and .-_ only"
        server.wait_for_line(r"sign-in failed for user 'plantadmin'", timeout_s=START_TIMEOUT_S)  # after the access
        # line of the health request, which came first
    finally:
        server.stop()
    output = "".join(server.output)
    assert WRONG_PASSWORD not in output and ADMIN_PASSWORD not in output
    records = _records(server.output)
    assert records, output
    for record in records:
        assert set(record) >= {"time", "level", "logger", "request_id", "message"}
        datetime.fromisoformat(str(record["time"]))
    access = [r for r in records if r["request_id"] == "proxy-trace-42"]
    assert any(r["logger"] == "uvicorn.access" and "/api/health" in str(r["message"]) and "200" in str(r["message"])
               for r in access), access
    sign_in = [r for r in records if "sign-in failed" in str(r["message"])]
    assert len(sign_in) == 1 and sign_in[0]["level"] == "WARNING" and sign_in[0]["request_id"] == made_up
    assert "127.0.0.1" in str(sign_in[0]["message"])


def _answers(base: str) -> bool:
    try:
        return httpx.get(base + "/api/health", timeout=5).status_code == 200
    except httpx.HTTPError:
        return False
