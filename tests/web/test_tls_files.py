"""``drivebench serve --tls-cert/--tls-key`` with the wrong files, as a shell runs it: which file, what is wrong and
what to do, exit 1, no traceback, no "PEM lib"."""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from drivebench.web.tls import self_signed, write_pair

pytestmark = pytest.mark.slow  # every test starts a `drivebench serve` process: `make test-quick` leaves them out


def _serve(tmp_path: Path, cert: Path, key: Path, prefix: list[str] | None = None) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("LC_ALL", "LC_MESSAGES", "LANG", "LANGUAGE")}
    env["DRIVEBENCH_DATABASE_URL"] = f"sqlite:///{tmp_path / 'serve.db'}"
    return subprocess.run([*(prefix or []), sys.executable, "-m", "drivebench.cli", "serve", "--port", "0",
                           "--tls-cert", str(cert), "--tls-key", str(key)],
                          env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False)


def _refused(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert "Traceback" not in done.stderr and "PEM lib" not in done.stderr and "_ssl.c" not in done.stderr
    return done.stderr


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    return write_pair(self_signed(["localhost"]), tmp_path / "tls")


def test_a_key_given_as_the_certificate_is_said_in_words(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    _, key = pair
    err = _refused(_serve(tmp_path, key, key))
    assert f"--tls-cert {key} holds a private key, not a certificate" in err and "swapped" in err


def test_a_certificate_given_as_the_key_is_said_in_words(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cert, _ = pair
    err = _refused(_serve(tmp_path, cert, cert))
    assert f"--tls-key {cert} holds a certificate, not a private key" in err


def test_a_garbage_file_is_said_in_words(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cert, key = pair
    garbage = tmp_path / "garbage.pem"
    garbage.write_bytes(b"\x00\x01 not PEM at all\n")
    err = _refused(_serve(tmp_path, garbage, key))
    assert f"--tls-cert {garbage} is not a PEM certificate" in err and "drivebench tls self-signed" in err
    err = _refused(_serve(tmp_path, cert, garbage))
    assert f"--tls-key {garbage} is not a PEM private key" in err


def test_a_folder_as_the_key_is_called_a_folder(tmp_path: Path, pair: tuple[Path, Path]) -> None:
    cert, key = pair
    err = _refused(_serve(tmp_path, cert, key.parent))
    assert f"--tls-key {key.parent} is a folder, not a file" in err and "no such file" not in err


def test_an_unreadable_key_names_the_file_and_the_user_who_must_read_it(tmp_path: Path,
                                                                         pair: tuple[Path, Path]) -> None:
    cert, key = pair
    key.chmod(0)
    # root reads every file; without these two capabilities it is held to the file's mode like any user
    setpriv = shutil.which("setpriv")
    if os.geteuid() == 0 and setpriv is None:
        pytest.skip("running as root without setpriv: every file is readable")
    prefix = [setpriv, "--bounding-set=-dac_override,-dac_read_search"] if os.geteuid() == 0 and setpriv else []
    err = _refused(_serve(tmp_path, cert, key, prefix))
    user = pwd.getpwuid(os.geteuid()).pw_name
    assert f"--tls-key {key}: the server runs as {user} (uid {os.geteuid()}), who may not read this file" in err
