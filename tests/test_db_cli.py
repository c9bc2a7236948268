"""`drivebench serve` against a database it cannot use, and `drivebench db upgrade | check` (issue 33): the real
processes, a real PostgreSQL (the suite's cluster; a closed port, an unknown user, an unknown host) and SQLite. Each
start that cannot work ends with exit 1 and words (which host, what failed, what to check), never a traceback."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import _free_port
from tests.pg_cluster import PostgresCluster

pytestmark = pytest.mark.slow  # real server processes: `make test-quick` leaves them out

REPO_ROOT = Path(__file__).resolve().parents[1]


def drivebench(*args: str, database_url: str, wait_s: float = 2, timeout_s: float = 120
               ) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DRIVEBENCH_DATABASE_URL": database_url, "DRIVEBENCH_DATABASE_WAIT_S": str(wait_s),
           "LANG": "C.UTF-8", "LC_ALL": "", "LC_MESSAGES": ""}
    return subprocess.run([sys.executable, "-m", "drivebench.cli", *args], cwd=REPO_ROOT, env=env, text=True,
                          capture_output=True, timeout=timeout_s)


def serve(database_url: str) -> subprocess.CompletedProcess[str]:
    """A start that must fail: if it did not, it would listen on a free port until the timeout."""
    return drivebench("serve", "--port", str(_free_port()), database_url=database_url)


def assert_words(result: subprocess.CompletedProcess[str], *expected: str) -> None:
    output = result.stdout + result.stderr
    assert result.returncode == 1, output
    assert "Traceback" not in output, output
    for text in expected:
        assert text in output, output


@pytest.fixture
def pg_url(postgres: PostgresCluster) -> Iterator[str]:
    url = postgres.new_database()
    yield url
    postgres.drop_database(url)


def test_serve_waits_for_a_closed_postgresql_port_then_exits_saying_what_to_check() -> None:
    port = _free_port()
    result = serve(f"postgresql+psycopg://drivebench:s3cret-pw@127.0.0.1:{port}/drivebench")
    assert_words(result, "Waiting up to 2 s for the database", f"127.0.0.1:{port} refused the connection",
                 "Check that PostgreSQL runs on that host and port")
    assert "s3cret-pw" not in result.stdout + result.stderr


@pytest.mark.postgresql
def test_serve_with_a_user_postgresql_does_not_know_says_authentication_failed(postgres: PostgresCluster) -> None:
    result = serve(f"postgresql+psycopg://nobody:wrong@127.0.0.1:{postgres.port}/postgres")
    assert_words(result, f"127.0.0.1:{postgres.port} did not accept the user nobody: authentication failed",
                 "Check the user name and the password in DRIVEBENCH_DATABASE_URL")


def test_serve_with_an_unknown_database_host_says_the_name_did_not_resolve() -> None:
    result = serve("postgresql+psycopg://drivebench:pw@no-such-host.invalid:5432/drivebench")
    assert_words(result, "The database host name no-such-host.invalid could not be resolved",
                 "Check the host name in DRIVEBENCH_DATABASE_URL")


@pytest.mark.postgresql
def test_serve_and_db_check_refuse_a_postgresql_schema_a_newer_release_upgraded(pg_url: str) -> None:
    import psycopg
    from sqlalchemy.engine import make_url

    assert drivebench("db", "upgrade", database_url=pg_url).returncode == 0
    parsed = make_url(pg_url)
    with psycopg.connect(host=parsed.host, port=parsed.port, user=parsed.username, dbname=parsed.database,
                         autocommit=True) as connection:
        connection.execute("UPDATE alembic_version SET version_num = '0099_from_a_newer_release'")
    expected = ("revision 0099_from_a_newer_release, which this release", "does not know",
                "Run the release that upgraded the database")
    assert_words(serve(pg_url), *expected)
    assert_words(drivebench("db", "check", database_url=pg_url), *expected)
    assert_words(drivebench("db", "upgrade", database_url=pg_url), *expected)


def test_db_check_and_upgrade_on_sqlite(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'drivebench.db'}"
    before = drivebench("db", "check", database_url=url)
    assert before.returncode == 1 and "run `drivebench db upgrade`" in before.stdout, before.stdout + before.stderr
    upgraded = drivebench("db", "upgrade", database_url=url)
    assert upgraded.returncode == 0 and "The database schema is current" in upgraded.stdout, upgraded.stderr
    after = drivebench("db", "check", database_url=url)
    assert after.returncode == 0 and "The database schema is current" in after.stdout, after.stderr

    with sqlite3.connect(tmp_path / "drivebench.db") as connection:
        connection.execute("UPDATE alembic_version SET version_num = '0099_from_a_newer_release'")
    assert_words(serve(url), "revision 0099_from_a_newer_release, which this release", "does not know")
