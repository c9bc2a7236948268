"""The container's contract with the server: the settings deploy/compose.yaml and the Dockerfile name are ones the
server reads (a misspelt name would be ignored without a word), the compose services agree with each other, and
the image's start (``serve --host 0.0.0.0`` with the admin from a secret file, https from settings) answers the
health check the image runs. The image itself is built and run by scripts/verify_container.sh (README, Container)."""

from __future__ import annotations

import json
import os
import re
import ssl
import subprocess
import sys
from pathlib import Path, PurePosixPath
from typing import Any

import httpx
import pytest
import yaml
from sqlalchemy.engine import make_url

from drivebench.cli import build_parser, health
from drivebench.config import REPO_ROOT, Settings
from tests.conftest import _free_port, wait_until
from tests.test_cli import run_cli
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

COMPOSE = REPO_ROOT / "deploy" / "compose.yaml"
DOCKERFILE = REPO_ROOT / "Dockerfile"
ADMIN_PASSWORD = "password of the first start"


def _settings_read() -> set[str]:
    prefix = str(Settings.model_config.get("env_prefix", ""))
    return {(prefix + name).upper() for name in Settings.model_fields}


def _interpolate(text: str, variables: dict[str, str]) -> str:
    """Compose's ``${NAME}``, ``${NAME:?message}`` and ``${NAME:-default}``, from ``variables``."""
    return re.sub(r"\$\{(\w+)(?::?[?-][^}]*)?\}", lambda m: variables[m.group(1)], text)


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    loaded = yaml.safe_load(COMPOSE.read_text(encoding="utf-8"))
    assert isinstance(loaded, dict)
    return loaded


def test_compose_sets_only_settings_the_server_reads(compose: dict[str, Any]) -> None:
    environment = compose["services"]["drivebench"]["environment"]
    assert environment, "the drivebench service sets no DRIVEBENCH_* settings"
    assert set(environment) - _settings_read() == set()
    image_env = set(re.findall(r"\b(DRIVEBENCH_\w+)=", DOCKERFILE.read_text(encoding="utf-8")))
    assert image_env and image_env - _settings_read() == set()


def test_compose_mounts_the_secret_and_the_volume_where_the_image_and_settings_expect_them(
        compose: dict[str, Any]) -> None:
    service = compose["services"]["drivebench"]
    secret = PurePosixPath(service["environment"]["DRIVEBENCH_ADMIN_PASSWORD_FILE"])
    assert secret.parent == PurePosixPath("/run/secrets")  # where compose mounts a service's secrets
    assert secret.name in service["secrets"] and "file" in compose["secrets"][secret.name]
    declared = re.search(r'^VOLUME \["([^"]+)"\]', DOCKERFILE.read_text(encoding="utf-8"), re.M)
    assert declared is not None
    mounts = dict(volume.split(":")[::-1] for volume in service["volumes"])
    assert mounts.get(declared.group(1)) in compose["volumes"]


def test_compose_database_url_names_the_postgres_service_its_user_database_and_password(
        compose: dict[str, Any]) -> None:
    variables = {"DRIVEBENCH_DB_PASSWORD": "pw-from-env", "DRIVEBENCH_SECRET_KEY": "k"}
    drivebench, postgres = compose["services"]["drivebench"], compose["services"]["postgres"]
    url = make_url(_interpolate(drivebench["environment"]["DRIVEBENCH_DATABASE_URL"], variables))
    database_env = {key: _interpolate(value, variables) for key, value in postgres["environment"].items()}
    assert url.drivername == "postgresql+psycopg"  # the driver of the image's [postgresql] extra
    assert '".[postgresql]"' in DOCKERFILE.read_text(encoding="utf-8")
    assert url.host in compose["services"] and url.host == "postgres"
    assert (url.username, url.password, url.database) == (
        database_env["POSTGRES_USER"], database_env["POSTGRES_PASSWORD"], database_env["POSTGRES_DB"])
    assert "postgres" in drivebench["depends_on"]
    assert postgres["healthcheck"]["test"][-4:] == ["--username", url.username, "--dbname", url.database]


def test_compose_and_image_health_checks_run_the_health_command(compose: dict[str, Any]) -> None:
    check = compose["services"]["drivebench"]["healthcheck"]["test"]
    image_check = re.search(r"^HEALTHCHECK .*CMD (\[.*\])$", DOCKERFILE.read_text(encoding="utf-8"), re.M)
    assert image_check is not None and ["CMD", *json.loads(image_check.group(1))] == check
    assert check[:2] == ["CMD", "drivebench"]
    assert build_parser().parse_args(check[2:]).func is health


def _health(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "drivebench.cli", "health"], capture_output=True, text=True,
                          env={**os.environ, **env}, cwd=REPO_ROOT, timeout=START_TIMEOUT_S)


def test_the_images_start_makes_the_admin_from_a_secret_file_and_answers_the_health_check_over_https(
        tmp_path: Path) -> None:
    secret = tmp_path / "admin_password"
    secret.write_text(ADMIN_PASSWORD + "\n")
    assert run_cli(["tls", "self-signed", "--host", "127.0.0.1", "--out", str(tmp_path / "tls")]) == 0
    cert = tmp_path / "tls" / "drivebench.crt"
    env = {"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'drivebench.db'}",
           "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "secret_key"), "DRIVEBENCH_PORT": str(_free_port()),
           "DRIVEBENCH_ADMIN_USER": "plantadmin", "DRIVEBENCH_ADMIN_PASSWORD_FILE": str(secret),
           "DRIVEBENCH_TLS_CERT_FILE": str(cert), "DRIVEBENCH_TLS_KEY_FILE": str(tmp_path / "tls" / "drivebench.key")}
    server = CliProcess("serve", "--host", "0.0.0.0", env=env)  # the image's CMD: refused without an admin
    try:
        server.wait_for_line(r"DriveBench on https://0\.0\.0\.0:")
        assert wait_until(lambda: _health(env).returncode == 0, START_TIMEOUT_S), _health(env).stderr
        assert _health(env).stdout.strip() == f"https://127.0.0.1:{env['DRIVEBENCH_PORT']}/api/health: ok"
        signed_in = httpx.post(f"https://127.0.0.1:{env['DRIVEBENCH_PORT']}/api/auth/login",
                               verify=ssl.create_default_context(cafile=str(cert)),
                               json={"name": "plantadmin", "password": ADMIN_PASSWORD}, timeout=10)
        assert signed_in.status_code == 200 and signed_in.json()["role"] == "admin", signed_in.text
        plain = _health({key: value for key, value in env.items() if not key.startswith("DRIVEBENCH_TLS")})
        assert plain.returncode == 1 and "No health answer from http://127.0.0.1:" in plain.stderr
    finally:
        server.stop()  # SIGTERM, as `docker stop` sends it (it fails the test if the server ignores it)
    assert "First start: created the admin plantadmin" in "".join(server.output)
    assert ADMIN_PASSWORD not in "".join(server.output)
    stopped = _health(env)
    assert stopped.returncode == 1 and "No health answer" in stopped.stderr
