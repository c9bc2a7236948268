"""Open websockets re-check their user (issue 27 item 6): a user disabled, given a lower role or a new password, or
a revoked API token, loses every live connection within seconds (code 4401/4403), and the nodes a closed
keep-alive socket held get quick stop at once. Over a real uvicorn server with real websocket clients; the admin
changes the user through the users API, as the Users page does, or another process changes the database."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, REPO_ROOT, fresh_channel, serve_app, wait_until

SERVO = 7
STATUS = f"/api/sessions/demo-plant/nodes/{SERVO}/control"
PASSWORDS = {"root": "root password", "eve": "engineer password"}
WAIT_S = 30.0  # generous: the machine is loaded; the sockets close within about a second


@dataclass
class Served:
    url: str
    root: httpx.Client
    db_url: str


@pytest.fixture
def served(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Served]:
    url = f"sqlite:///{tmp_path / 'drivebench.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(url)
    accounts.create_user("root", PASSWORDS["root"], Role.ADMIN)
    accounts.create_user("eve", PASSWORDS["eve"], Role.ENGINEER)
    root_token = accounts.issue_token("root", "test", Role.ADMIN).secret
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    try:
        with serve_app(app) as base, httpx.Client(base_url=base, timeout=30,
                                                  headers={"Authorization": f"Bearer {root_token}"}) as root:
            yield Served(base, root, url)
    finally:
        database.dispose(url)


@dataclass
class Eve:
    """Eve's API client (a signed-in browser's cookie, or an API token) and the headers her websocket sends."""

    http: httpx.Client
    socket_headers: dict[str, str]
    token_id: int | None = None


def _eve_signed_in(served: Served) -> Eve:
    http = httpx.Client(base_url=served.url, timeout=30, headers={"Origin": served.url})
    answer = http.post("/api/auth/login", json={"name": "eve", "password": PASSWORDS["eve"]})
    assert answer.status_code == 200, answer.text
    http.headers["X-CSRF-Token"] = answer.json()["csrf_token"]
    return Eve(http, {"Cookie": f"drivebench_session={http.cookies['drivebench_session']}"})


def _eve_with_token(served: Served) -> Eve:
    issued = served.root.post("/api/tokens", json={"name": "line script", "user": "eve", "role": "engineer"})
    assert issued.status_code == 201, issued.text
    bearer = {"Authorization": f"Bearer {issued.json()['token']}"}
    return Eve(httpx.Client(base_url=served.url, timeout=30, headers=bearer), bearer, issued.json()["id"])


def _socket(served: Served, eve: Eve, path: str) -> ClientConnection:
    return connect(served.url.replace("http", "ws", 1) + path, open_timeout=30,
                   additional_headers={**eve.socket_headers, "Origin": served.url})


@dataclass
class KeepAlive:
    """A page's keep-alive socket, sending ``{"cmd": "keepalive"}`` every 0.3 s until the server closes it."""

    socket: ClientConnection
    held: list[int] = field(default_factory=list)
    closed_with: int | None = None
    ended: threading.Event = field(default_factory=threading.Event)

    def start(self) -> KeepAlive:
        threading.Thread(target=self._run, daemon=True).start()
        return self

    def _run(self) -> None:
        try:
            while True:
                self.socket.send(json.dumps({"cmd": "keepalive"}))
                self.held = json.loads(self.socket.recv(timeout=10))["nodes"]
                self.ended.wait(0.3)
        except ConnectionClosed as exc:
            self.closed_with = exc.rcvd.code if exc.rcvd else None
        except TimeoutError:
            pass
        finally:
            self.ended.set()


def _state(served: Served) -> dict[str, Any]:
    answer = served.root.get(STATUS)
    assert answer.status_code == 200, answer.text
    return dict(answer.json())


def _enable_servo(served: Served, eve: Eve, keepalive: KeepAlive) -> None:
    """Eve's tab enables node 7 through the drive control API and holds it with its keep-alive socket."""
    assert wait_until(lambda: _state(served)["state"] == "switch_on_disabled", WAIT_S)
    tab = {"X-Drive-Panel": "tab-eve"}
    for step in ("shutdown", "switch_on"):
        assert eve.http.post(f"{STATUS}/commands/{step}", headers=tab).status_code == 200
    enabled = confirmed(eve.http, "POST", f"{STATUS}/commands/enable_operation", json={}, headers=tab)
    assert enabled.status_code == 200, enabled.text
    assert wait_until(lambda: _state(served)["state"] == "operation_enabled" and keepalive.held == [SERVO], WAIT_S)


def _disable(served: Served, eve: Eve) -> None:
    assert served.root.patch("/api/users/eve", json={"disabled": True}).status_code == 200


def _disable_elsewhere(served: Served, eve: Eve) -> None:
    """Another process on the same database (the CLI; another server alike): this server hears no event of it."""
    done = subprocess.run([sys.executable, "-m", "drivebench.cli", "users", "disable", "eve"], cwd=REPO_ROOT,
                          env={**os.environ, "DRIVEBENCH_DATABASE_URL": served.db_url}, capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stdout + done.stderr


def _to_viewer(served: Served, eve: Eve) -> None:
    assert served.root.patch("/api/users/eve", json={"role": "viewer"}).status_code == 200


def _new_password(served: Served, eve: Eve) -> None:
    assert served.root.put("/api/users/eve/password", json={"password": "a new password"}).status_code == 204


def _revoke(served: Served, eve: Eve) -> None:
    assert served.root.delete(f"/api/tokens/{eve.token_id}").status_code == 200


@pytest.mark.parametrize(("credential", "change"), [
    (_eve_signed_in, _disable), (_eve_signed_in, _to_viewer), (_eve_signed_in, _new_password),
    (_eve_signed_in, _disable_elsewhere), (_eve_with_token, _disable), (_eve_with_token, _to_viewer),
    (_eve_with_token, _revoke), (_eve_with_token, _disable_elsewhere)],
    ids=["cookie-disabled", "cookie-viewer", "cookie-new-password", "cookie-disabled-by-another-process",
         "token-disabled", "token-viewer", "token-revoked", "token-disabled-by-another-process"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_keepalive_socket_of_a_user_who_lost_access_closes_and_its_node_stops(served: Served, credential: Any,
                                                                              change: Any) -> None:
    eve = credential(served)
    with _socket(served, eve, "/ws/sessions/demo-plant/keepalive?client=tab-eve") as socket:
        keepalive = KeepAlive(socket).start()
        try:
            _enable_servo(served, eve, keepalive)
            change(served, eve)
            # REST refuses her keep-alive (at once; a change by another process after the accounts cache's 2 s)
            assert wait_until(lambda: eve.http.post(f"{STATUS}/keepalive", headers={"X-Drive-Panel": "tab-eve"}
                                                    ).status_code in (401, 403), WAIT_S)
            assert keepalive.ended.wait(WAIT_S), "the keep-alive socket stays open and keeps node 7 enabled"
        finally:
            keepalive.ended.set()
    eve.http.close()
    assert keepalive.closed_with in (4401, 4403)
    assert wait_until(lambda: _state(served)["state"] != "operation_enabled", WAIT_S)
    status = _state(served)
    assert not status["armed"]
    # stopped because her access ended, not later by the keep-alive deadline
    assert "may no longer hold it" in status["last_trip"] and "eve" in status["last_trip"]


@pytest.mark.parametrize(("credential", "change"), [
    (_eve_signed_in, _to_viewer), (_eve_signed_in, _disable), (_eve_with_token, _revoke)],
    ids=["cookie-viewer", "cookie-disabled", "token-revoked"])
@pytest.mark.slow
def test_a_change_through_this_server_has_stopped_her_drive_when_it_answers(served: Served, credential: Any,
                                                                             change: Any) -> None:
    """The account change re-checks the live connections at once: when the admin's request is answered, her
    keep-alive socket is refused and node 7 is stopped because her access ended (not a second later by the
    periodic re-check, nor by a keep-alive deadline that a busy server let pass first)."""
    eve = credential(served)
    with _socket(served, eve, "/ws/sessions/demo-plant/keepalive?client=tab-eve") as socket:
        keepalive = KeepAlive(socket).start()
        try:
            _enable_servo(served, eve, keepalive)
            change(served, eve)
            status = _state(served)  # read right after the answer
            assert not status["armed"], status
            assert "may no longer hold it" in (status["last_trip"] or "") and "eve" in status["last_trip"], status
            assert keepalive.ended.wait(WAIT_S), "the keep-alive socket stays open"
        finally:
            keepalive.ended.set()
    eve.http.close()
    assert keepalive.closed_with in (4401, 4403)


def test_the_control_panel_socket_of_a_disabled_user_closes_and_its_node_stops(served: Served) -> None:
    eve = _eve_signed_in(served)
    with _socket(served, eve, f"/ws/sessions/demo-plant/nodes/{SERVO}/control?panel=tab-eve") as panel, \
            _socket(served, eve, "/ws/sessions/demo-plant/keepalive?client=tab-eve") as socket:
        keepalive = KeepAlive(socket).start()
        try:
            _enable_servo(served, eve, keepalive)
            _disable(served, eve)
            with pytest.raises(ConnectionClosed) as closed:
                while True:
                    panel.recv(timeout=WAIT_S)
                    panel.send(json.dumps({"cmd": "keepalive"}))
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 4401
            assert wait_until(lambda: _state(served)["state"] != "operation_enabled", WAIT_S)
            assert keepalive.ended.wait(WAIT_S) and keepalive.closed_with == 4401
        finally:
            keepalive.ended.set()
    eve.http.close()


def test_the_monitor_socket_of_a_disabled_user_closes(served: Served) -> None:
    eve = _eve_signed_in(served)
    with _socket(served, eve, "/ws/sessions/demo-plant/monitor") as monitor:
        assert json.loads(monitor.recv(timeout=WAIT_S))["type"] == "hello"
        _disable(served, eve)
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                monitor.recv(timeout=WAIT_S)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 4401
        assert "sign" in closed.value.rcvd.reason.lower()
    eve.http.close()


def test_sockets_of_other_users_stay_open(served: Served) -> None:
    """The re-check closes nothing that may stay open: disabling otto leaves eve's monitor streaming."""
    eve = _eve_signed_in(served)
    with _socket(served, eve, "/ws/sessions/demo-plant/monitor") as monitor:
        assert json.loads(monitor.recv(timeout=WAIT_S))["type"] == "hello"
        other = served.root.post("/api/users", json={"name": "otto", "password": "otto password", "role": "viewer"})
        assert other.status_code == 201
        assert served.root.patch("/api/users/otto", json={"disabled": True}).status_code == 200
        updates = 0
        while updates < 40:  # the monitor sends about ten a second: several re-checks have passed
            assert json.loads(monitor.recv(timeout=WAIT_S))["type"] == "update"
            updates += 1
    eve.http.close()
