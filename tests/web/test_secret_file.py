"""The cookie signing key file: never read half written, never an empty key (issue 33)."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drivebench.config import REPO_ROOT

pytestmark = pytest.mark.slow  # every test starts server or key-making processes: `make test-quick` leaves them out

_MAKE_KEY = ("import sys, time\n"
             "from drivebench.web.access import secret_key\n"
             "while time.time() < float(sys.argv[1]): pass\n"
             "print(secret_key())\n")


def _env(key_file: Path, **more: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DRIVEBENCH_SECRET_KEY", "LC_ALL", "LC_MESSAGES", "LANG")}
    return {**env, "DRIVEBENCH_SECRET_KEY_FILE": str(key_file), **more}


def test_serve_refuses_an_empty_key_file_in_words(tmp_path: Path) -> None:
    key_file = tmp_path / "secret_key"
    key_file.touch(mode=0o600)  # what a process that created the file but had not written it yet left
    server = subprocess.Popen([sys.executable, "-m", "drivebench.cli", "serve", "--port", "0"], cwd=tmp_path,
                              env=_env(key_file, DRIVEBENCH_DATABASE_URL=f"sqlite:///{tmp_path / 'db.sqlite'}"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _, err = server.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        server.kill()
        server.communicate()
        raise AssertionError("serve started with an empty signing key") from None
    assert server.returncode == 1 and "Traceback" not in err, err
    assert f"The secret key file {key_file} is empty" in err and "Delete the file" in err
    assert key_file.read_text() == "", "the file is left for the admin to look at"


def test_processes_starting_together_share_one_whole_key(tmp_path: Path) -> None:
    key_file = tmp_path / "keys" / "secret_key"
    start_at = str(time.time() + 8)  # all started and waiting before any of them makes the key
    runs = [subprocess.Popen([sys.executable, "-c", _MAKE_KEY, start_at], cwd=REPO_ROOT, env=_env(key_file),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(6)]
    results = [run.communicate(timeout=120) for run in runs]
    keys = {out.strip() for out, _ in results}
    assert all(run.returncode == 0 for run in runs), [err for _, err in results]
    assert len(keys) == 1 and len(keys.pop()) > 40
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    assert [p.name for p in key_file.parent.iterdir()] == ["secret_key"], "no temporary file left behind"


def test_serve_says_when_it_cannot_make_the_key_file(tmp_path: Path) -> None:
    folder = tmp_path / "read-only"
    folder.mkdir(mode=0o555)
    setpriv = shutil.which("setpriv")
    if os.geteuid() == 0 and setpriv is None:
        pytest.skip("running as root without setpriv: every folder is writable")
    # root writes every folder; without these two capabilities it is held to the folder's mode like any user
    prefix = [setpriv, "--bounding-set=-dac_override,-dac_read_search"] if os.geteuid() == 0 and setpriv else []
    done = subprocess.run([*prefix, sys.executable, "-m", "drivebench.cli", "serve", "--port", "0"], cwd=tmp_path,
                          env=_env(folder / "secret_key",
                                   DRIVEBENCH_DATABASE_URL=f"sqlite:///{tmp_path / 'db.sqlite'}"),
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"Cannot make the secret key file {folder / 'secret_key'}: Permission denied" in done.stderr
