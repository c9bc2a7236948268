"""`drivebench serve` does not let slow clients hold it (issue 28 item 14): a connection that trickles its request
headers is closed at the header deadline, and past the connection limit the connection that has waited longest for
its headers makes room, so /api/health still answers. Real servers and raw sockets; generous bounds, no timing
asserted beyond "closed within a minute"."""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from drivebench.web import serving
from drivebench.web.app import create_app
from tests.conftest import _free_port, serve_app
from tests.transport.test_multiprocess import CliProcess

REQUEST_START = b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\n"
WITHIN_S = 60.0


def _trickling(port: int, count: int) -> list[socket.socket]:
    sockets = []
    for _ in range(count):
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        sock.sendall(REQUEST_START)
        sock.setblocking(False)
        sockets.append(sock)
    return sockets


def _closed_by_server(sock: socket.socket, line: int) -> bool:
    """Sends one more header line; True once the server has closed the connection."""
    try:
        if sock.recv(4096) == b"":
            return True
    except BlockingIOError:
        pass
    except OSError:
        return True
    try:
        sock.send(f"X-Slow-{line}: a\r\n".encode())
    except BlockingIOError:
        return False
    except OSError:
        return True
    return False


def _trickle_until_closed(sockets: list[socket.socket], within_s: float = WITHIN_S) -> list[socket.socket]:
    """Keep the sockets trickling header lines; the ones still open after ``within_s``."""
    open_ones, line, deadline = list(sockets), 0, time.monotonic() + within_s
    while open_ones and time.monotonic() < deadline:
        line += 1
        open_ones = [s for s in open_ones if not _closed_by_server(s, line)]
        time.sleep(0.5)
    return open_ones


@contextlib.contextmanager
def _served(tmp_path: Path) -> Iterator[int]:
    port = _free_port()
    server = CliProcess("serve", "--port", str(port),
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}",
                             "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "secret_key")})
    try:
        server.wait_for_line(r"DriveBench on http://")
        deadline = time.monotonic() + WITHIN_S
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=10).status_code == 200:
                    break
            time.sleep(0.2)
        yield port
    finally:
        server.stop()


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_serve_closes_connections_that_trickle_their_headers(tmp_path: Path) -> None:
    with _served(tmp_path) as port:
        sockets = _trickling(port, 30)
        try:
            still_open = _trickle_until_closed(sockets)
            assert still_open == [], f"{len(still_open)} of 30 trickling connections still open"
            assert httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=30).status_code == 200
        finally:
            for sock in sockets:
                sock.close()


def test_past_the_connection_limit_the_longest_waiting_connection_makes_room() -> None:
    options = serving.uvicorn_options(header_timeout_s=3600, connections=20)  # no deadline within the test
    with serve_app(create_app(), **options) as url:
        port = int(url.rsplit(":", 1)[1])
        sockets = _trickling(port, 30)
        try:
            assert httpx.get(f"{url}/api/health", timeout=30).status_code == 200  # room made for it
            still_open = _trickle_until_closed(sockets, within_s=5)
            assert len(still_open) < 20, len(still_open)  # the server holds at most its limit
            assert sockets[-1] in still_open  # the newest were kept, the longest-waiting shed
        finally:
            for sock in sockets:
                sock.close()


def test_a_kept_alive_connection_serves_requests_after_the_deadline_was_re_armed() -> None:
    with serve_app(create_app(), **serving.uvicorn_options(header_timeout_s=2)) as url, \
            httpx.Client(base_url=url, timeout=30) as http:
        for _ in range(3):
            assert http.get("/api/health").status_code == 200  # one connection, a deadline per request
