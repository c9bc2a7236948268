"""`drivebench serve` as a process of its own, where the real server's headers matter: the forwarded headers uvicorn
believes (none by default: a client cannot choose the address the sign-in limit counts), ``--allowed-host`` and
``--public-url``, and a session stamp changed by another process on the same database."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from tests.conftest import _free_port, wait_until
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

PASSWORDS = {"root": "root password", "eve": "engineer password", "vera": "viewer password"}


@dataclass
class Served:
    url: str
    db_url: str
    root_token: str
    eve_cookie: str
    """A sign-in of eve taken when the server started."""


@contextlib.contextmanager
def drivebench_serve(tmp: Path, *options: str) -> Iterator[Served]:
    """``drivebench serve --port P *options`` on a database of its own with three users."""
    db_url = f"sqlite:///{tmp / 'drivebench.db'}"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", db_url)
        database.upgrade_to_head(db_url)
        for name, role in (("root", Role.ADMIN), ("eve", Role.ENGINEER), ("vera", Role.VIEWER)):
            accounts.create_user(name, PASSWORDS[name], role)
        root_token = accounts.issue_token("root", "test", Role.ADMIN).secret
    env = {"DRIVEBENCH_DATABASE_URL": db_url, "DRIVEBENCH_SECRET_KEY_FILE": str(tmp / "key"),
           "FORWARDED_ALLOW_IPS": "*"}  # uvicorn's own variable must not open the door either
    server = CliProcess("serve", "--port", str(_free_port()), *options, env=env)
    try:
        url = server.wait_for_line(r"DriveBench on (http://\S+)").group(1)
        assert wait_until(lambda: _answers(url), START_TIMEOUT_S), "".join(server.output)
        signed_in = httpx.post(f"{url}/api/auth/login", json={"name": "eve", "password": PASSWORDS["eve"]})
        assert signed_in.status_code == 200, signed_in.text
        yield Served(url, db_url, root_token, signed_in.cookies["drivebench_session"])
    finally:
        server.stop()
        database.dispose(db_url)


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    with drivebench_serve(tmp_path_factory.mktemp("serve"), "--allowed-host", "bench.example",
                          "--public-url", "https://drivebench.plant.example") as running:
        yield running


def _answers(url: str) -> bool:
    try:
        return httpx.get(f"{url}/api/health", timeout=1).status_code == 200
    except httpx.HTTPError:
        return False


def test_a_locked_address_cannot_sign_in_by_naming_another(tmp_path: Path) -> None:
    with drivebench_serve(tmp_path) as served:  # as started by default
        _lock_the_address_and_try_another(served)


def _lock_the_address_and_try_another(served: Served) -> None:
    for attempt in range(20):  # 20 names, one failure each: the address (127.0.0.1) is locked, no name is
        wrong = httpx.post(f"{served.url}/api/auth/login", json={"name": f"nobody{attempt}", "password": "guess"},
                           headers={"X-Forwarded-For": f"10.9.9.{attempt}"})
        assert wrong.status_code == 401, wrong.text
    for forwarded in ({"X-Forwarded-For": "10.9.9.9"}, {"Forwarded": "for=10.9.9.9"}, {}):
        locked = httpx.post(f"{served.url}/api/auth/login", json={"name": "vera", "password": PASSWORDS["vera"]},
                            headers=forwarded)
        assert locked.status_code == 429, (forwarded, locked.text)
        assert "Too many failed sign-ins from 127.0.0.1" in locked.json()["detail"]


def test_serve_answers_to_its_names_and_links_to_its_public_url(served: Served) -> None:
    root = {"Authorization": f"Bearer {served.root_token}"}
    evil = httpx.get(f"{served.url}/api/sessions", headers={**root, "Host": "evil.example"})
    assert evil.status_code == 400 and "not a name of this server" in evil.json()["detail"]
    made = httpx.post(f"{served.url}/api/share-links", json={"ttl_minutes": 5},
                      headers={**root, "Host": "bench.example:8301", "Origin": "https://bench.example"})
    assert made.status_code == 201, made.text
    assert made.json()["url"] == f"https://drivebench.plant.example/remote/{made.json()['token']}"


def test_another_server_s_disable_ends_the_session_for_good(served: Served) -> None:
    cookie = {"drivebench_session": served.eve_cookie}
    assert httpx.get(f"{served.url}/api/auth/me", cookies=cookie).status_code == 200
    with pytest.MonkeyPatch.context() as patch:  # this process is the other server of the same database
        patch.setattr(settings, "database_url", served.db_url)
        accounts.set_disabled("eve", True)
        accounts.set_disabled("eve", False)
    assert wait_until(lambda: httpx.get(f"{served.url}/api/auth/me", cookies=cookie).status_code == 401,
                      accounts.DIRECTORY_TTL_S + 10)


def test_serve_refuses_a_public_url_that_is_no_address(tmp_path: Path) -> None:
    server = CliProcess("serve", "--port", "0", "--public-url", "drivebench.example",
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}"})
    server.wait_for_line("is not a web address")
    assert server.process.wait(timeout=START_TIMEOUT_S) == 1
