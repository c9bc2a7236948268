"""``drivebench serve | simulate | hub``: the server on a socketcand bus shared with a simulator process, and the
messages a user gets instead of tracebacks."""

from __future__ import annotations

import io
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from drivebench.cli import main
from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.transport.hub import start_hub_thread
from tests.conftest import wait_until
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess, start_simulator

DEMO_NODE_IDS = [3, 5, 7, 12]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def run_cli(args: list[str]) -> int:
    """``main(args)`` in a thread of its own: a browser test earlier in the session leaves Playwright's event loop
    running in the main thread, where ``asyncio.run`` refuses to start."""
    codes: list[int] = []
    worker = threading.Thread(target=lambda: codes.append(main(args)))
    worker.start()
    worker.join(timeout=START_TIMEOUT_S)
    assert codes, f"drivebench {' '.join(args)} did not end"
    return codes[0]


def poll(fetch: Callable[[], object], timeout_s: float, what: str) -> object:
    """Call ``fetch`` until it returns something true (connection errors count as not yet)."""
    last: list[object] = [None]

    def fetched() -> bool:
        try:
            last[0] = fetch()
        except httpx.TransportError as exc:
            last[0] = exc
        return bool(last[0]) and not isinstance(last[0], Exception)
    assert wait_until(fetched, timeout_s), f"{what}: still {last[0]!r} after {timeout_s} s"
    return last[0]


@pytest.mark.slow  # measured 54-120 s of the quick subset on the loaded 2 cores
def test_serve_opens_a_socketcand_bus_shared_with_a_simulator_process(tmp_path: Path) -> None:
    """`drivebench serve --bus socketcand:127.0.0.1:PORT/can0` against the hub, drives simulated by another
    process: health answers, the session is listed, a scan finds the four drives with live heartbeat states."""
    with start_hub_thread(port=0) as hub:
        bus = f"socketcand:127.0.0.1:{hub.port}/can0"
        simulator = start_simulator(bus)
        port = free_port()
        server = CliProcess("serve", "--port", str(port), "--bus", bus,
                            env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}"})
        try:
            base = f"http://127.0.0.1:{port}"
            with httpx.Client(base_url=base, timeout=10) as api:
                health = poll(lambda: api.get("/api/health").json(), START_TIMEOUT_S, "health")
                assert isinstance(health, dict) and health["status"] == "ok" and health["sessions"] == 1

                (session,) = api.get("/api/sessions").json()
                assert (session["interface"], session["channel"], session["simulated"]) == ("socketcand", "can0",
                                                                                            False)
                assert session["bus"] == f"{bus}@500000"

                found = api.post(f"/api/sessions/{session['id']}/scan", json={"timeout_s": 1.0})
                assert found.status_code == 200, found.text
                assert sorted(node["node_id"] for node in found.json()) == DEMO_NODE_IDS

                def live_states() -> list[str] | None:
                    nodes = api.get(f"/api/sessions/{session['id']}/nodes").json()
                    live = [n["nmt_state"] for n in nodes if n["state_from_heartbeat"]]
                    return live if len(live) == len(DEMO_NODE_IDS) else None

                assert poll(live_states, 15, "heartbeat states") == ["Pre-operational"] * len(DEMO_NODE_IDS)
        finally:
            codes = [server.stop(), simulator.stop()]
    # uvicorn shuts down gracefully on SIGTERM, then raises the signal again so the exit status tells why it ended
    assert codes in ([0, 0], [-signal.SIGTERM, 0]), "serve and simulate end on SIGTERM"


def test_serve_with_an_unreachable_gateway_says_what_to_check(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    assert run_cli(["serve", "--port", "0", "--bus", f"socketcand:127.0.0.1:{port}/can0"]) == 1
    err = capsys.readouterr().err
    assert f"Cannot reach the socketcand gateway at 127.0.0.1:{port}" in err
    assert f"drivebench hub --port {port}" in err and "Traceback" not in err


@pytest.mark.parametrize(("bus", "message"), [
    ("nosuchcan:can0@500000", "Unknown CAN interface 'nosuchcan'"),
    ("socketcand:gateway/can0", "socketcand:HOST:PORT/CHANNEL"),
    ("virtual:x@2000000", "bitrate"),
    ("not a bus", "is not a bus specification"),
])
def test_serve_with_a_bad_bus_ends_with_a_message(bus: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(["serve", "--port", "0", "--bus", bus]) == 1
    err = capsys.readouterr().err
    assert err.startswith("drivebench: ") and message in err and "Traceback" not in err


def test_hub_refuses_non_loopback_addresses_without_allow_remote(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(["hub", "--host", "0.0.0.0", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "Refusing to listen on 0.0.0.0" in err and "--allow-remote" in err


@pytest.fixture
def cli_db(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """A database of the test's own: users are never created in the shared one."""
    url = f"sqlite:///{tmp_path / 'cli.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    yield url
    database.dispose(url)


def test_serve_on_all_interfaces_needs_an_admin_and_says_how(cli_db: str, capsys: pytest.CaptureFixture[str],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    assert run_cli(["serve", "--host", "0.0.0.0", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "Refusing to listen on 0.0.0.0" in err and "drivebench users add admin --role admin" in err
    with pytest.raises(SystemExit):  # no way around it any more
        main(["serve", "--host", "0.0.0.0", "--allow-remote"])
    assert "unrecognized arguments: --allow-remote" in capsys.readouterr().err

    monkeypatch.setattr("sys.stdin", io.StringIO("a long admin password\n"))
    assert run_cli(["users", "add", "admin", "--role", "admin", "--password-stdin"]) == 0
    assert "Signing in is on" in capsys.readouterr().out
    assert accounts.authentication_configured()
    assert accounts.verify_password("admin", "a long admin password").name == "admin"
    # now the check passes and the command goes on to its buses: a bad one ends it with that message
    assert run_cli(["serve", "--host", "0.0.0.0", "--port", "0", "--bus", "not a bus"]) == 1
    assert "is not a bus specification" in capsys.readouterr().err


def test_users_and_tokens_commands(cli_db: str, capsys: pytest.CaptureFixture[str],
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    for name, role in [("root", "admin"), ("eve", "engineer")]:
        monkeypatch.setattr("sys.stdin", io.StringIO(f"{name} password 123\n"))
        assert run_cli(["users", "add", name, "--role", role, "--password-stdin"]) == 0
    monkeypatch.setattr("sys.stdin", io.StringIO("x\n"))
    assert run_cli(["users", "add", "short", "--role", "viewer", "--password-stdin"]) == 1
    assert "too short" in capsys.readouterr().err
    assert run_cli(["users", "disable", "root"]) == 1
    assert "last enabled admin" in capsys.readouterr().err
    assert run_cli(["tokens", "create", "nightly", "--user", "eve", "--role", "admin"]) == 1
    assert "cannot have the admin role" in capsys.readouterr().err
    assert run_cli(["tokens", "create", "nightly", "--user", "eve", "--role", "viewer"]) == 0
    secret = capsys.readouterr().out.strip()
    assert secret.startswith("dbt_") and accounts.verify_token(secret).name == "eve"
    monkeypatch.setattr("sys.stdin", io.StringIO("eve password 456\n"))
    assert run_cli(["users", "passwd", "eve", "--password-stdin"]) == 0
    assert run_cli(["users", "disable", "eve"]) == 0
    capsys.readouterr()
    assert run_cli(["users", "list"]) == 0
    listing = capsys.readouterr().out
    assert re.search(r"eve\s+engineer\s+disabled", listing) and re.search(r"root\s+admin\s+active", listing)
    assert run_cli(["tokens", "list"]) == 0 and secret not in capsys.readouterr().out


FIRST_PASSWORD = "first admin password"


def test_serve_makes_the_first_admin_from_a_secret_file_once_and_never_prints_it(
        cli_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    secret = tmp_path / "admin_password"
    secret.write_text(FIRST_PASSWORD + "\n")  # a secret file's line break is not part of the password
    monkeypatch.setattr(settings, "admin_user", "plantadmin")
    monkeypatch.setattr(settings, "admin_password_file", secret)
    # on all interfaces, as in the container: the admin is made before the check, which then passes (a bad bus ends it)
    assert run_cli(["serve", "--host", "0.0.0.0", "--port", "0", "--bus", "not a bus"]) == 1
    out, err = capsys.readouterr()
    assert "created the admin plantadmin" in out and "is not a bus specification" in err
    assert FIRST_PASSWORD not in out + err
    assert accounts.verify_password("plantadmin", FIRST_PASSWORD).role.label == "admin"

    secret.write_text("a changed password\n")  # a restart with other settings leaves the users alone
    assert run_cli(["serve", "--port", "0", "--bus", "not a bus"]) == 1
    out = capsys.readouterr().out
    assert "Users exist already" in out and "a changed password" not in out
    assert accounts.verify_password("plantadmin", FIRST_PASSWORD).name == "plantadmin"
    assert [user.name for user in accounts.list_users()] == ["plantadmin"]


def test_first_admin_settings_in_error_say_what_to_fix_and_make_nobody(
        cli_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from pydantic import SecretStr

    monkeypatch.setattr(settings, "admin_password", SecretStr("pw7x!"))
    assert run_cli(["serve", "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert "The password is too short" in err and "pw7x!" not in err
    monkeypatch.setattr(settings, "admin_password_file", tmp_path / "missing")
    assert run_cli(["serve", "--port", "0"]) == 1
    assert "keep one" in capsys.readouterr().err
    monkeypatch.setattr(settings, "admin_password", None)
    assert run_cli(["serve", "--port", "0"]) == 1
    assert f"Cannot read the admin password from DRIVEBENCH_ADMIN_PASSWORD_FILE={tmp_path / 'missing'}: " \
           "No such file or directory" in capsys.readouterr().err
    assert accounts.list_users() == []


def test_simulate_on_an_unknown_interface_ends_with_a_message(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(["simulate", "--bus", "nosuchcan:can0"]) == 1
    assert "Unknown CAN interface 'nosuchcan'" in capsys.readouterr().err


def test_hub_with_a_bridge_to_a_missing_adapter_ends_with_a_message(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(["hub", "--port", "0", "--bridge", "nosuchcan:can0@500000"]) == 1
    captured = capsys.readouterr()
    assert "Unknown CAN interface 'nosuchcan'" in captured.err and "Traceback" not in captured.err
    assert "socketcand hub on" not in captured.out, "the hub never announced itself"


def test_hub_on_a_port_in_use_ends_with_a_message(capsys: pytest.CaptureFixture[str]) -> None:
    with start_hub_thread(port=0) as hub:
        assert run_cli(["hub", "--port", str(hub.port)]) == 1
    err = capsys.readouterr().err
    assert f"cannot listen on 127.0.0.1:{hub.port}" in err and "--port" in err and "Traceback" not in err


def _drivebench(args: list[str], tmp_path: Path, **language: str) -> subprocess.CompletedProcess[str]:
    """The command as a shell runs it, with only these language variables set."""
    env = {k: v for k, v in os.environ.items() if k not in ("LC_ALL", "LC_MESSAGES", "LANG", "LANGUAGE")}
    return subprocess.run([sys.executable, "-m", "drivebench.cli", *args], env={**env, **language}, cwd=tmp_path,
                          capture_output=True, text=True, timeout=60, check=False)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_the_command_speaks_the_language_of_the_shell(tmp_path: Path) -> None:
    """LANG=de_DE.UTF-8 gives German messages, help and errors; LC_ALL and LC_MESSAGES come first, as in C."""
    refused = _drivebench(["tls", "self-signed", "--host", "plant.local", "--days", "0"], tmp_path,
                          LANG="de_DE.UTF-8")
    assert refused.returncode == 1
    assert refused.stderr == "drivebench: --days 0: Ein Zertifikat wird für 1 bis 3650 Tage ausgestellt.\n"
    made = _drivebench(["tls", "self-signed", "--host", "plant.local", "--out", "tls"], tmp_path, LANG="de_DE.UTF-8")
    assert made.returncode == 0, made.stderr
    assert made.stdout.startswith("Zertifikat tls/drivebench.crt (für plant.local, 825 Tage)")
    assert "SHA-256-Fingerabdruck" in made.stdout and "Starten mit: drivebench serve" in made.stdout
    assert "den Webserver starten" in _drivebench(["--help"], tmp_path, LC_MESSAGES="de_DE").stdout
    english = _drivebench(["tls", "self-signed", "--host", "plant.local", "--days", "0"], tmp_path,
                          LC_ALL="C", LANG="de_DE.UTF-8")
    assert english.stderr == "drivebench: --days 0: a certificate is made for 1 to 3650 days.\n"
    assert "run the web server" in _drivebench(["--help"], tmp_path).stdout  # nothing set: English
