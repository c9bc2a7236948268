"""A plant's PostgreSQL database created with the SQL_ASCII encoding (initdb on a host without a UTF-8 locale, as a
compose trial's database container was): psycopg hands every text column back as bytes there unless the connection
asks for UTF-8, and SQLAlchemy's first connect died reading the server version ("cannot use a string pattern on a
bytes-like object"): a traceback instead of a start."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import psycopg
import pytest
from sqlalchemy import text

from drivebench.services.storage import database, reachability
from tests.pg_cluster import PostgresCluster

pytestmark = pytest.mark.postgresql


@pytest.fixture
def sql_ascii_url(postgres: PostgresCluster) -> Iterator[str]:
    name = f"t_sql_ascii_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(f"host=127.0.0.1 port={postgres.port} user=postgres dbname=postgres",
                         autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE \"{name}\" ENCODING 'SQL_ASCII' LC_COLLATE 'C' LC_CTYPE 'C' "
                           "TEMPLATE template0")
    url = postgres.url(name)
    yield url
    database.dispose(url)
    postgres.drop_database(url)


def test_a_sql_ascii_database_is_usable_and_keeps_german_text(sql_ascii_url: str) -> None:
    assert reachability.probe(sql_ascii_url) is None
    database.upgrade_to_head(sql_ascii_url)
    with database.engine(sql_ascii_url).begin() as connection:
        connection.execute(text("CREATE TABLE words (said TEXT)"))
        connection.execute(text("INSERT INTO words VALUES (:said)"), {"said": "Hochlaufzeit größer als 650 s"})
        assert connection.execute(text("SELECT said FROM words")).scalar_one() == "Hochlaufzeit größer als 650 s"
