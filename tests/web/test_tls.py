"""https for a plant network: `drivebench tls self-signed`, `serve --tls-cert/--tls-key`, Secure cookies, HSTS on
request only, and certificate mistakes said in words before the server starts."""

from __future__ import annotations

import ssl
import stat
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from cryptography import x509

from drivebench.config import settings
from drivebench.errors import InvalidValue
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from drivebench.web.tls import check_pair, self_signed, write_pair
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app
from tests.test_cli import run_cli


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    """A certificate and key made by the CLI, as a user makes them."""
    assert run_cli(["tls", "self-signed", "--host", "127.0.0.1", "--host", "localhost",
                    "--out", str(tmp_path / "tls")]) == 0
    return tmp_path / "tls" / "drivebench.crt", tmp_path / "tls" / "drivebench.key"


@pytest.fixture
def signed_in_db(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    url = f"sqlite:///{tmp_path / 'tls.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(url)
    accounts.create_user("anna", "anna's password", Role.ADMIN)
    yield
    database.dispose(url)


def _client(cert: Path, base: str) -> httpx.Client:
    return httpx.Client(base_url=base, verify=ssl.create_default_context(cafile=str(cert)), timeout=10)


def test_the_cli_makes_a_certificate_for_the_names_given_with_a_private_key(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(["tls", "self-signed", "--host", "plant-7.local", "--host", "10.0.0.7", "--out", str(tmp_path)]) == 0
    cert, key = tmp_path / "drivebench.crt", tmp_path / "drivebench.key"
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    names = x509.load_pem_x509_certificate(cert.read_bytes()).extensions.get_extension_for_class(
        x509.SubjectAlternativeName).value
    assert names.get_values_for_type(x509.DNSName) == ["plant-7.local"]
    assert [str(ip) for ip in names.get_values_for_type(x509.IPAddress)] == ["10.0.0.7"]
    printed = capsys.readouterr().out
    assert "SHA-256 fingerprint" in printed and f"--tls-cert {cert}" in printed
    check_pair(cert, key)  # the two belong together


def test_https_serves_the_app_and_the_sign_in_cookie_is_secure(pair: tuple[Path, Path], signed_in_db: None) -> None:
    cert, key = pair
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app, ssl_certfile=str(cert), ssl_keyfile=str(key)) as url, _client(cert, url) as client:
        assert url.startswith("https://")
        assert client.get("/api/health").status_code == 200
        answer = client.post("/api/auth/login", json={"name": "anna", "password": "anna's password"},
                             headers={"Origin": url, "Sec-Fetch-Site": "same-origin"})
        assert answer.status_code == 200, answer.text
        cookie = answer.headers["set-cookie"].lower()
        assert "secure" in cookie and "httponly" in cookie and "samesite=strict" in cookie
        assert "strict-transport-security" not in answer.headers  # off unless asked for
        with pytest.raises(httpx.TransportError):  # plain http on the https port is not served
            httpx.get(url.replace("https://", "http://") + "/api/health", timeout=5)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_hsts_is_sent_over_https_when_asked_for(pair: tuple[Path, Path], app_db_url: str) -> None:
    cert, key = pair
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms", hsts=True)
    with serve_app(app, ssl_certfile=str(cert), ssl_keyfile=str(key)) as url, _client(cert, url) as client:
        assert client.get("/api/health").headers["strict-transport-security"] == "max-age=31536000"


def test_certificate_mistakes_are_said_before_the_server_starts(tmp_path: Path) -> None:
    first, second = self_signed(["plant-a"]), self_signed(["plant-b"])
    cert_a, _ = write_pair(first, tmp_path / "a")
    _, key_b = write_pair(second, tmp_path / "b")
    with pytest.raises(InvalidValue, match="the key does not belong to the certificate"):
        check_pair(cert_a, key_b)
    with pytest.raises(InvalidValue, match="--tls-cert needs --tls-key"):
        check_pair(cert_a, None)
    with pytest.raises(InvalidValue, match="no such file"):
        check_pair(tmp_path / "missing.crt", key_b)
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate")
    with pytest.raises(InvalidValue, match=r"junk\.pem"):
        check_pair(junk, key_b)
    with pytest.raises(InvalidValue, match="at least one host"):
        self_signed([])


def test_serve_refuses_a_key_without_its_certificate_in_words(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    _, key = write_pair(self_signed(["localhost"]), tmp_path)
    assert run_cli(["serve", "--tls-key", str(key)]) == 1
    assert "--tls-key needs --tls-cert too" in capsys.readouterr().err
    assert run_cli(["serve", "--hsts"]) == 1
    assert "--hsts needs --tls-cert" in capsys.readouterr().err
