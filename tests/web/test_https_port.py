"""``drivebench serve --tls-cert/--tls-key`` answers plain http to its port with a 400 in words naming the https
address (issue 33: it was an empty reply), and still serves pages and websockets over https."""

from __future__ import annotations

import socket
import ssl
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import websockets.sync.client

from drivebench.web.https_port import plain_http_answer
from tests.conftest import _free_port, wait_until
from tests.test_cli import run_cli
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess


@pytest.fixture
def https_server(tmp_path: Path) -> Iterator[tuple[int, ssl.SSLContext]]:
    """`drivebench serve --demo` over https on a free port, as a plant runs it; its port and a client context
    that trusts its certificate."""
    assert run_cli(["tls", "self-signed", "--host", "127.0.0.1", "--out", str(tmp_path / "tls")]) == 0
    cert, key = tmp_path / "tls" / "drivebench.crt", tmp_path / "tls" / "drivebench.key"
    port = _free_port()
    server = CliProcess("serve", "--demo", "--port", str(port), "--tls-cert", str(cert), "--tls-key", str(key),
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}",
                             "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "secret_key")})
    trusting = ssl.create_default_context(cafile=str(cert))
    try:
        server.wait_for_line(r"DriveBench on https://")
        assert wait_until(lambda: _healthy(port, trusting), START_TIMEOUT_S), "".join(server.output)
        yield port, trusting
    finally:
        server.stop()


def _healthy(port: int, context: ssl.SSLContext) -> bool:
    try:
        return httpx.get(f"https://127.0.0.1:{port}/api/health", verify=context, timeout=30).status_code == 200
    except httpx.HTTPError:
        return False


def _raw_plain_request(port: int, request: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
        sock.sendall(request)
        answer = b""
        while chunk := sock.recv(4096):
            answer += chunk
    return answer


def test_plain_http_to_the_https_port_gets_a_400_in_words_and_https_still_serves(
        https_server: tuple[int, ssl.SSLContext]) -> None:
    port, trusting = https_server
    plain = httpx.get(f"http://127.0.0.1:{port}/sessions/demo-plant", timeout=60)
    assert plain.status_code == 400 and plain.headers["content-type"].startswith("text/html")
    assert f'This port speaks HTTPS: open <a href="https://127.0.0.1:{port}/">' in plain.text
    assert plain.headers["connection"] == "close"

    german = httpx.get(f"http://127.0.0.1:{port}/", headers={"Accept-Language": "de", "Host": "plant-7.local:8443"},
                       timeout=60)
    assert german.status_code == 400 and german.headers["content-language"] == "de"
    assert "Dieser Port spricht HTTPS: öffnen Sie https://plant-7.local:8443/" in german.text.replace(
        '<a href="https://plant-7.local:8443/">', "").replace("</a>", "")

    without_host = _raw_plain_request(port, b"GET / HTTP/1.0\r\n\r\n")  # no Host: the server's own address
    assert without_host.startswith(b"HTTP/1.1 400 ") and f"https://127.0.0.1:{port}/".encode() in without_host

    with httpx.Client(base_url=f"https://127.0.0.1:{port}", verify=trusting, timeout=60) as client:
        page = client.get("/", headers={"Accept": "text/html"})
        assert page.status_code == 200 and "<html" in page.text
        assert client.get("/api/health").json()["status"] == "ok"
    with websockets.sync.client.connect(f"wss://127.0.0.1:{port}/ws/sessions/demo-plant/nodes", ssl=trusting,
                                        open_timeout=60) as node_list:
        assert "<" in str(node_list.recv(timeout=60))  # the node list's html over TLS


@pytest.mark.parametrize(("host", "named"), [
    ("plant-7.local", "https://plant-7.local:80/"),  # no port: the client reached the port as http's 80
    ("[fd00::7]:8443", "https://[fd00::7]:8443/"),
    ('evil"><script>', "https://10.0.0.7:8443/"),  # not a host name: the server's own address, nothing echoed
    ("plant:99999", "https://10.0.0.7:8443/"),
])
def test_the_answer_names_the_host_the_client_asked_for_when_it_is_a_host(host: str, named: str) -> None:
    answer = plain_http_answer(f"GET / HTTP/1.1\r\nHost: {host}\r\n\r\n".encode(), ("10.0.0.7", 8443)).decode()
    assert f'<a href="{named}">{named}</a>' in answer
    assert "<script>" not in answer
    head, body = answer.split("\r\n\r\n", 1)
    assert f"Content-Length: {len(body.encode())}" in head
