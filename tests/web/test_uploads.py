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
        sock.sendall(f"POST /api/profiles HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: {FIFTY_MB}\r\n"
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
        sock.sendall(f"POST /api/profiles HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n"
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


BATCH_LIMIT = 64 * 1024 * 1024


def padded_eds(size: int, product: str) -> bytes:
    """The servo EDS with comment lines up to ``size`` bytes, as another product (its own profile id)."""
    text = SERVO_EDS.read_bytes().replace(b"ProductName=", b"ProductName=" + product.encode() + b" ", 1)
    filler = b"; " + b"c" * 1000 + b"\r\n"
    return text + filler * ((size - len(text)) // len(filler))


def test_a_batch_of_12_mb_passes_the_one_file_limit_and_is_read(server: str) -> None:
    files = [("files", (f"big{n}.eds", padded_eds(4 * 1024 * 1024, f"Big{n}"))) for n in range(3)]
    response = requests.post(f"{server}/api/profiles/batch", files=files, timeout=120)
    assert response.status_code == 200, response.text[:300]
    rows = response.json()["rows"]
    assert [row["outcome"] for row in rows] != [] and all(row["outcome"] != "refused" for row in rows), rows
    for row in rows:
        requests.delete(f"{server}/api/profiles/{row['profile_id']}", timeout=30)


def test_a_declared_batch_over_64_mib_is_refused_in_words(server: str) -> None:
    boundary = "drivebench-batch"
    with connect(server) as sock:
        sock.sendall(f"POST /api/profiles/batch HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: {70 * 2**20}\r\n"
                     f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n".encode())
        status, headers, body = read_response(sock)
    assert status == 413 and headers["content-type"] == "application/problem+json"
    assert json.loads(body)["detail"] == "The file is 70 MB; uploads are limited to 64 MB."


def test_a_chunked_batch_over_64_mib_gets_a_413_in_words(server: str) -> None:
    boundary = "drivebench-batch-chunked"
    total = BATCH_LIMIT + 8 * 1024 * 1024

    def framed() -> Iterator[bytes]:
        head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"files\"; filename=\"all.zip\"\r\n"
                "Content-Type: application/zip\r\n\r\n").encode()
        yield f"{len(head):X}\r\n".encode() + head + b"\r\n"
        for _ in range(total // CHUNK):
            yield f"{CHUNK:X}\r\n".encode() + b"x" * CHUNK + b"\r\n"

    with connect(server) as sock:
        sock.sendall(f"POST /api/profiles/batch HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n"
                     f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n".encode())
        sent = send_until_answered(sock, framed())
        status, headers, body = read_response(sock)
    assert status == 413 and headers["content-type"] == "application/problem+json"
    assert json.loads(body)["detail"] == "The file is larger than 64 MB; uploads are limited to 64 MB."
    assert sent > 5 * 1024 * 1024  # the batch limit counted, not the one-file limit
    assert requests.get(f"{server}/api/health", timeout=10).status_code == 200


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
    """A multipart upload with the file name as raw UTF-8 in the part header (no client escaping of NUL and
    control characters, as a hand-made request would send it)."""
    boundary = "drivebench-names"
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n").encode() + content + f"\r\n--{boundary}--\r\n".encode()
    return api.post("/api/profiles", content=body,
                    headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})


def shipped_state() -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(SHIPPED.iterdir()) if p.is_file()}


@pytest.mark.parametrize(("name", "shown"), [
    ("../../etc/passwd.eds", "passwd.eds"),
    ("C:\\x\\..\\y.eds", "y.eds"),
    ("/absolute/servo.EDS", "servo.EDS"),
    ("nul\x00byte.eds", "nulbyte.eds"),
    ("\u202eevil\u200b\x07.eds", "evil.eds"),
    (".eds", ".eds"),
])
def test_a_file_name_never_becomes_a_path(api: TestClient, user_dir: Path, tmp_path: Path, name: str,
                                          shown: str) -> None:
    before = shipped_state()
    response = upload(api, name, SERVO_EDS.read_bytes())
    assert response.status_code == 201, response.text
    profile = response.json()
    assert profile["uploaded_as"] == shown
    stored = sorted(p.name for p in user_dir.iterdir())
    assert stored == [f"{profile['id']}.eds"]
    assert all((p.parent == user_dir) for p in user_dir.rglob("*"))
    assert sorted(p.name for p in tmp_path.rglob("*.eds")) == stored
    assert shipped_state() == before
    listed = {p["id"]: p for p in api.get("/api/profiles").json()}
    assert listed[profile["id"]]["uploaded_as"] == shown and not listed[profile["id"]]["builtin"]


def test_a_500_character_name_is_shortened_for_showing_and_the_id_for_storing(api: TestClient, user_dir: Path
                                                                                ) -> None:
    response = upload(api, "a" * 496 + ".eds", SERVO_EDS.read_bytes())
    assert response.status_code == 201, response.text
    profile = response.json()
    assert len(profile["uploaded_as"]) == 120 and profile["uploaded_as"].endswith("a….eds")
    assert len(profile["id"]) <= 80
    assert [p.name for p in user_dir.iterdir()] == [f"{profile['id']}.eds"]


@pytest.mark.parametrize("name", ["CON.eds", "nul.eds", "com1.eds", "LPT9.dcf"])
def test_windows_device_names_are_refused_in_words(api: TestClient, user_dir: Path, name: str) -> None:
    response = upload(api, name, SERVO_EDS.read_bytes())
    assert response.status_code == 422
    assert "device name on Windows" in response.json()["detail"]
    assert response.json()["source"] == name
    assert not user_dir.exists() or list(user_dir.iterdir()) == []


def test_a_long_profile_id_is_refused_in_words(api: TestClient) -> None:
    profile = json.loads((SHIPPED / "lenze-8400-motec-canopen.json").read_text(encoding="utf-8"))
    profile["id"] = "x" * 300
    response = upload(api, "long.json", json.dumps(profile).encode())
    assert response.status_code == 422
    assert response.json()["detail"] == ("long.json: the profile id is 300 characters long; at most 100 are "
                                         "allowed (it names the stored file)")


def test_an_upload_cannot_replace_a_shipped_profile(api: TestClient, user_dir: Path) -> None:
    before = shipped_state()
    shipped = (SHIPPED / "lenze-8400-motec-canopen.json").read_bytes()
    for name in ("lenze-8400-motec-canopen.json", "../../device_profiles/lenze-8400-motec-canopen.json"):
        response = upload(api, name, shipped)
        assert response.status_code == 422
        assert "belongs to a built-in profile" in response.json()["detail"]
    assert shipped_state() == before
    assert not user_dir.exists() or list(user_dir.iterdir()) == []


def test_a_name_only_of_a_suffix_and_an_unknown_suffix_are_answered_in_words(api: TestClient) -> None:
    response = upload(api, "..", SERVO_EDS.read_bytes())
    assert response.status_code == 422
    assert response.json()["detail"].startswith(
        "..: unknown profile file type (none); use .json, .eds, .dcf, .xdd or .xdc")


def test_deleting_an_upload_forgets_the_name_it_came_in_as(api: TestClient, user_dir: Path) -> None:
    profile = upload(api, "../x/Servo Drive.eds", SERVO_EDS.read_bytes()).json()
    assert profile["uploaded_as"] == "Servo Drive.eds"
    assert api.delete(f"/api/profiles/{profile['id']}").status_code == 204
    assert json.loads((user_dir.parent / "user-profiles.names.json").read_text(encoding="utf-8")) == {}
    assert list(user_dir.iterdir()) == []


def test_the_refusal_speaks_the_browsers_language_and_writes_its_numbers(server: str) -> None:
    too_big = b"[" + b"0," * int(3.7 * 1024 * 1024) + b"0]"
    response = requests.post(f"{server}/api/tools/planner/check", data=too_big, timeout=30,
                             headers={"Content-Type": "application/json", "Accept-Language": "de-DE,de;q=0.9"})
    assert response.status_code == 413
    assert response.json()["detail"] == "Der Inhalt der Anfrage ist 7,4 MB groß; Uploads sind auf 5 MB begrenzt."
