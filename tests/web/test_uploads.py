"""Uploads that are too big or badly named, against a real server (uvicorn) and through the app.

Too big: a 50 MB upload is refused with 413 in words while the client has sent only a small part of it (declared
length) or soon after it passes the limit (chunked); the server answers the next request at once.
Badly named: whatever the uploaded file is called, the stored file is named after the profile id, inside the
upload directory, never over a shipped profile; the name the user gave is kept only to show.
"""

from __future__ import annotations

import json
import select
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
import requests
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app
from tests.conftest import serve_app

FIFTY_MB = 50 * 1024 * 1024
CHUNK = 64 * 1024
SERVO_EDS = REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds"
SHIPPED = REPO_ROOT / "device_profiles"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The app (no plant) in uvicorn, uploads into a temporary directory."""
    work = tmp_path_factory.mktemp("uploads")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", work / "profiles")
        patch.setattr(settings, "database_url", f"sqlite:///{work / 'db.sqlite'}")
        with serve_app(create_app()) as url:
            yield url


def connect(url: str) -> socket.socket:
    parts = urlsplit(url)
    return socket.create_connection((parts.hostname, parts.port), timeout=20)


def read_response(sock: socket.socket) -> tuple[int, dict[str, str], bytes]:
    """Status, headers and body of one HTTP/1.1 response with Content-Length (what the server sends)."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        assert chunk, f"the server closed the connection without an answer: {data!r}"
        data += chunk
    head, body = data.split(b"\r\n\r\n", 1)
    lines = head.decode("latin-1").split("\r\n")
    headers = {k.strip().lower(): v.strip() for k, v in (line.split(":", 1) for line in lines[1:])}
    while len(body) < int(headers.get("content-length", "0")):
        chunk = sock.recv(65536)
        if not chunk:
            break
        body += chunk
    return int(lines[0].split()[1]), headers, body


def multipart_head(boundary: str, filename: str) -> bytes:
    return (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{filename}\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n").encode()


def send_until_answered(sock: socket.socket, chunks: Iterator[bytes]) -> int:
    """Send chunks until the server answers (or stops reading); the number of bytes sent by then."""
    sent = 0
    for chunk in chunks:
        readable, _, _ = select.select([sock], [], [], 0)
        if readable:
            return sent
        try:
            sock.sendall(chunk)
        except (BrokenPipeError, ConnectionResetError):
            return sent
        sent += len(chunk)
    select.select([sock], [], [], 20)  # the whole body went out: wait for the answer
    return sent


def test_a_declared_50_mb_upload_is_refused_before_the_body_is_sent(server: str) -> None:
    boundary = "drivebench-big"
    head = multipart_head(boundary, "huge.eds")
    with connect(server) as sock:
        sock.sendall(f"POST /api/profiles HTTP/1.1\r\nHost: test\r\nContent-Length: {FIFTY_MB}\r\n"
                     f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n".encode() + head)
        sent = send_until_answered(sock, iter([b"x" * CHUNK] * 16))  # at most 1 MB of the 50
        status, headers, body = read_response(sock)
    assert status == 413
    assert headers["content-type"] == "application/problem+json"
    problem = json.loads(body)
    assert problem["title"] == "Upload too large"
    assert problem["detail"] == "The file is 50 MB; uploads are limited to 5 MB."
    assert sent <= 16 * CHUNK < FIFTY_MB
    assert requests.get(f"{server}/api/health", timeout=10).status_code == 200


def test_a_chunked_50_mb_upload_is_cut_soon_after_the_limit(server: str) -> None:
    boundary = "drivebench-chunked"

    def chunks() -> Iterator[bytes]:
        yield multipart_head(boundary, "huge.eds")
        for _ in range(FIFTY_MB // CHUNK):
            yield b"x" * CHUNK

    def framed() -> Iterator[bytes]:  # HTTP/1.1 chunked transfer coding
        for chunk in chunks():
            yield f"{len(chunk):X}\r\n".encode() + chunk + b"\r\n"

    with connect(server) as sock:
        sock.sendall(f"POST /api/profiles HTTP/1.1\r\nHost: test\r\nTransfer-Encoding: chunked\r\n"
                     f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n".encode())
        sent = send_until_answered(sock, framed())
        status, _, body = read_response(sock)
    assert status == 413
    assert json.loads(body)["detail"] == "The file is larger than 5 MB; uploads are limited to 5 MB."
    assert sent < FIFTY_MB / 2  # the limit plus what the socket buffers held, not the whole upload
    assert requests.get(f"{server}/api/health", timeout=10).status_code == 200


def test_a_big_json_body_is_refused_too_and_htmx_gets_a_fragment(server: str) -> None:
    too_big = b"[" + b"0," * (3 * 1024 * 1024) + b"0]"
    response = requests.post(f"{server}/api/tools/planner/check", data=too_big,
                             headers={"Content-Type": "application/json"}, timeout=30)
    assert response.status_code == 413
    assert response.json()["detail"] == "The request body is 6 MB; uploads are limited to 5 MB."
    fragment = requests.post(f"{server}/ui/profiles", data=too_big, timeout=30,
                             headers={"HX-Request": "true", "Content-Type": "multipart/form-data; boundary=x"})
    assert fragment.status_code == 413
    assert 'role="alert"' in fragment.text and "The file is 6 MB; uploads are limited to 5 MB." in fragment.text


def test_an_upload_within_the_limit_reaches_the_profile_checks(server: str) -> None:
    content = SERVO_EDS.read_bytes()
    response = requests.post(f"{server}/api/profiles", files={"file": ("servo.eds", content)}, timeout=30)
    assert response.status_code == 201, response.text
    requests.delete(f"{server}/api/profiles/{response.json()['id']}", timeout=30)


# --- file names -------------------------------------------------------------------------------------------------
@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    return tmp_path / "user-profiles"


@pytest.fixture
def api(user_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    monkeypatch.setattr(settings, "database_url", f"sqlite:///{tmp_path / 'db.sqlite'}")
    with TestClient(create_app()) as client:
        yield client


def upload(api: TestClient, name: str, content: bytes) -> Any:
    return api.post("/api/profiles", files={"file": (name, content)})


def shipped_state() -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(SHIPPED.iterdir()) if p.is_file()}
