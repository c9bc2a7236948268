"""The last enabled admin stays (issue 28 item 12): two admins disabling each other at the same moment, through
real servers (one uvicorn on SQLite; two on one PostgreSQL database), never both succeed; and a server with no
enabled admin (no sign-in) serves only clients on this machine, whatever the Host header says."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from drivebench.web.state import app_state
from tests.conftest import serve_app
from tests.web.test_access import own_db

__all__ = ["own_db"]  # the fixture shared with test_access

ROUNDS = 8
PASSWORD = "a long password"


@pytest.fixture
def shared_db(database_url: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[str]:
    monkeypatch.setattr(settings, "database_url", database_url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(database_url)
    yield database_url


def _two_admins(round_no: int) -> dict[str, str]:
    """Two new admins (and their tokens); every admin before them is disabled."""
    names = [f"a{round_no}", f"b{round_no}"]
    for name in names:
        accounts.create_user(name, PASSWORD, Role.ADMIN)
    for user in accounts.list_users():
        if user.name not in names and not user.disabled:
            accounts.set_disabled(user.name)
    return {name: accounts.issue_token(name, "race", Role.ADMIN).secret for name in names}


def _at_once(calls: list[tuple[str, str, str]]) -> list[int]:
    """PATCH ``/api/users/{target}`` disabled=true from ``base`` with ``token``, all calls let go together."""
    start = threading.Barrier(len(calls))
    statuses = [0] * len(calls)

    def call(number: int, base: str, token: str, target: str) -> None:
        with httpx.Client(base_url=base, timeout=60) as http:
            http.get("/api/health")  # the connection is open before the barrier
            start.wait()
            statuses[number] = http.patch(f"/api/users/{target}", json={"disabled": True},
                                          headers={"Authorization": f"Bearer {token}"}).status_code

    threads = [threading.Thread(target=call, args=(n, *c)) for n, c in enumerate(calls)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    return statuses


def _race(bases: list[str]) -> None:
    for round_no in range(ROUNDS):
        tokens = _two_admins(round_no)
        a, b = tokens
        statuses = _at_once([(bases[0], tokens[a], b), (bases[-1], tokens[b], a)])
        assert statuses.count(200) == 1 and set(statuses) <= {200, 401, 409}, (round_no, statuses)
        assert accounts.authentication_configured(), round_no


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_two_admins_disabling_each_other_leave_one(shared_db: str) -> None:
    with contextlib.ExitStack() as stack:
        bases = [stack.enter_context(serve_app(create_app()))]
        if shared_db.startswith("postgresql"):  # two servers of one database
            bases.append(stack.enter_context(serve_app(create_app())))
        _race(bases)


# --- no enabled admin: this machine only --------------------------------------------------------------------------
@pytest.mark.parametrize("address", ["192.0.2.7", "10.1.2.3", "fd00::7"])
def test_without_an_admin_another_machine_is_refused(own_db: str, address: str) -> None:
    app = create_app()
    with TestClient(app, client=(address, 40000)) as remote, TestClient(app, client=("127.0.0.1", 40000)) as local:
        for method, path in (("GET", "/api/sessions"), ("GET", "/"), ("POST", "/api/sessions")):
            refused = remote.request(method, path, json={"bus": "virtual:x@500000"})
            assert refused.status_code == 403, (method, path, refused.text)
            assert refused.headers["content-type"] == "application/problem+json", path
            assert "only from this machine" in refused.json()["detail"], refused.json()
            assert "drivebench users add" in refused.json()["hint"]
            assert refused.headers["x-frame-options"] == "DENY"
        assert remote.get("/api/health").status_code == 200  # a probe still sees the server is up
        assert local.get("/api/sessions").status_code == 200
        accounts.create_user("root", PASSWORD, Role.ADMIN)
        app_state(app).accounts.forget()  # made by "the CLI": this app reads it at once
        assert remote.get("/api/sessions").status_code == 401  # now everyone signs in, from anywhere
