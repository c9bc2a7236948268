"""The container's contract with the server: the settings deploy/compose.yaml and the Dockerfile name are ones the
server reads (a misspelt name would be ignored without a word), the compose services agree with each other, and
the image's start (``serve --host 0.0.0.0`` with the admin from a secret file, https from settings) answers the
health check the image runs. The image itself is built and run by scripts/verify_container.sh (README, Container)."""

from __future__ import annotations

import json
import os
import re
import shutil
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
COMPOSE_PROGRAMS = {"Compose v2": str(REPO_ROOT / ".cache" / "compose-v2" / "docker-compose"),
                    "docker-compose 1.29": "docker-compose"}
"""The two Compose programs a plant runs the files with; `make compose` (a step of `make test`) brings both."""


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
    """The password is a secret file both services read (never in the URL or an environment value, where `docker
    inspect` shows it)."""
    drivebench, postgres = compose["services"]["drivebench"], compose["services"]["postgres"]
    environment = drivebench["environment"]
    url = make_url(environment["DRIVEBENCH_DATABASE_URL"])
    assert url.drivername == "postgresql+psycopg"  # the driver of the image's [postgresql] extra
    assert '".[postgresql]"' in DOCKERFILE.read_text(encoding="utf-8")
    assert url.host in compose["services"] and url.host == "postgres"
    assert url.password is None
    assert (url.username, url.database) == (postgres["environment"]["POSTGRES_USER"],
                                            postgres["environment"]["POSTGRES_DB"])
    password_file = PurePosixPath(environment["DRIVEBENCH_DATABASE_PASSWORD_FILE"])
    assert password_file == PurePosixPath(postgres["environment"]["POSTGRES_PASSWORD_FILE"])
    assert password_file.parent == PurePosixPath("/run/secrets")
    assert password_file.name in drivebench["secrets"] and password_file.name in postgres["secrets"]
    assert "file" in compose["secrets"][password_file.name]
    assert "POSTGRES_PASSWORD" not in postgres["environment"]
    assert "postgres" in drivebench["depends_on"]
    assert postgres["healthcheck"]["test"][-4:] == ["--username", url.username, "--dbname", url.database]


def test_compose_keeps_secrets_in_files_and_the_plant_names_in_env(compose: dict[str, Any]) -> None:
    """Debian's docker-compose 1.29 refuses a top-level `name:`; the secret key is a file (DRIVEBENCH_SECRET_KEY
    as an environment value shows in `docker inspect`); the line's names come from .env, not the compose file."""
    assert "name" not in compose
    environment = compose["services"]["drivebench"]["environment"]
    assert "DRIVEBENCH_SECRET_KEY" not in environment
    key_file = PurePosixPath(environment["DRIVEBENCH_SECRET_KEY_FILE"])
    assert key_file.parent == PurePosixPath("/run/secrets") and "file" in compose["secrets"][key_file.name]
    for name in ("DRIVEBENCH_ALLOWED_HOSTS", "DRIVEBENCH_PUBLIC_URL"):
        assert environment[name].startswith("${" + name), f"{name} is written into compose.yaml, not read from .env"
    example = (REPO_ROOT / "deploy" / "env.example").read_text(encoding="utf-8")
    given = {line.split("=", 1)[0] for line in example.splitlines() if "=" in line and not line.startswith("#")}
    needed = set(re.findall(r"\$\{(\w+):\?", COMPOSE.read_text(encoding="utf-8")))
    assert needed <= given, f"env.example lacks {needed - given}"
    tls = yaml.safe_load((REPO_ROOT / "deploy" / "compose.tls.yaml").read_text(encoding="utf-8"))
    tls_env = tls["services"]["drivebench"]["environment"]
    assert set(tls_env) <= _settings_read()
    for variable in ("DRIVEBENCH_TLS_CERT_FILE", "DRIVEBENCH_TLS_KEY_FILE"):
        assert PurePosixPath(tls_env[variable]).name in tls["secrets"]


def _env_values(text: str) -> dict[str, str]:
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))


@pytest.mark.parametrize("program", COMPOSE_PROGRAMS)
def test_compose_v2_and_debians_docker_compose_1_29_take_the_files_with_the_names_from_env(
        program: str, tmp_path: Path) -> None:
    """Each program renders compose.yaml alone and with the TLS variant (``config`` reads and checks the files as
    ``up`` does, without an engine) and takes the line's names from .env; without them it refuses, in the words
    compose.yaml gives."""
    binary = shutil.which(COMPOSE_PROGRAMS[program])
    assert binary, f"{program} is not on this machine: `make compose` brings it"
    deploy = tmp_path / "deploy"
    shutil.copytree(REPO_ROOT / "deploy", deploy)
    env = deploy / ".env"
    env.write_text((deploy / "env.example").read_text(encoding="utf-8"), encoding="utf-8")
    expected = _env_values(env.read_text(encoding="utf-8"))

    def config(*files: str) -> subprocess.CompletedProcess[str]:
        chosen = [arg for name in files for arg in ("-f", str(deploy / name))]
        return subprocess.run([binary, "--env-file", str(env), *chosen, "config"], capture_output=True, text=True,
                              cwd=tmp_path, timeout=120)

    for files in (("compose.yaml",), ("compose.yaml", "compose.tls.yaml")):
        rendered = config(*files)
        assert rendered.returncode == 0, f"{program} {files}: {rendered.stderr}"
        services = yaml.safe_load(rendered.stdout)["services"]
        environment = services["drivebench"]["environment"]
        for name in ("DRIVEBENCH_ALLOWED_HOSTS", "DRIVEBENCH_PUBLIC_URL"):
            assert environment[name] == expected[name], (program, name, environment[name])
        assert "DRIVEBENCH_SECRET_KEY" not in environment and set(services) == {"drivebench", "postgres"}
        if "compose.tls.yaml" in files:
            assert "DRIVEBENCH_TLS_CERT_FILE" in environment
    env.write_text("", encoding="utf-8")
    refused = config("compose.yaml")
    said = re.findall(r"\$\{\w+:\?([^}]+)\}", COMPOSE.read_text(encoding="utf-8"))  # a program names one of them
    assert refused.returncode != 0 and said and any(words in refused.stderr for words in said), refused.stderr


def test_the_database_password_file_goes_into_the_url_and_a_missing_one_is_said_in_words(tmp_path: Path) -> None:
    password = tmp_path / "db_password"
    password.write_text("p@ss/word\n")
    url = "postgresql+psycopg://drivebench@postgres:5432/drivebench"
    settings = Settings(database_url=url, database_password_file=password)
    assert make_url(settings.database_url).password == "p@ss/word"
    missing = subprocess.run([sys.executable, "-m", "drivebench.cli", "db", "check"], capture_output=True, text=True,
                             env={**os.environ, "DRIVEBENCH_DATABASE_URL": url,
                                  "DRIVEBENCH_DATABASE_PASSWORD_FILE": str(tmp_path / "nope")},
                             cwd=REPO_ROOT, timeout=START_TIMEOUT_S)
    assert missing.returncode != 0 and "Traceback" not in missing.stderr
    assert f"DRIVEBENCH_DATABASE_PASSWORD_FILE {tmp_path / 'nope'}: cannot read it" in missing.stderr


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
