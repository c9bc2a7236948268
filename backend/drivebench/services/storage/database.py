"""One database for planned networks, parameter sets, audit log and users: SQLAlchemy 2 + Alembic.

The URL comes from ``settings.database_url`` (``DRIVEBENCH_DATABASE_URL``): a SQLite file by default, PostgreSQL
when several servers share one store. The schema is owned by the Alembic migrations in ``drivebench/migrations``;
``upgrade_to_head`` runs them (at app start-up and in tests), nothing calls ``create_all``.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Connection, Engine, create_engine, event, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import DeclarativeBase, Session, sessionmaker

from drivebench.config import settings
from drivebench.errors import SchemaTooNew
from drivebench.i18n import N_, Text

if TYPE_CHECKING:
    from alembic.config import Config

MIGRATIONS_DIR = Path(__file__).resolve().parents[2] / "migrations"


class Base(DeclarativeBase):
    """Declarative base of every table (``services/storage/models.py``)."""


_engines: dict[str, Engine] = {}
_engines_lock = threading.Lock()
_upgrade_lock = threading.Lock()
_UPGRADE_LOCK_KEY = 0x44726976  # "Driv": one advisory lock id for schema upgrades on PostgreSQL


def _sqlite_foreign_keys(dbapi_connection: object, _record: object) -> None:
    cursor = dbapi_connection.cursor()  # type: ignore[attr-defined]
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()


def engine(url: str | None = None) -> Engine:
    """The engine for ``url`` (default: ``settings.database_url``), created once per URL."""
    url = url or settings.database_url
    with _engines_lock:
        existing = _engines.get(url)
        if existing is not None:
            return existing
        parsed = make_url(url)
        connect_args: dict[str, object] = {}
        if parsed.get_backend_name() == "sqlite":
            connect_args["check_same_thread"] = False  # sessions are used from worker threads, one at a time
            connect_args["timeout"] = 30  # a writer waits for another server's write on a loaded machine (5 s gave up)
            if parsed.database and parsed.database != ":memory:":
                _private_file(Path(parsed.database))
        elif parsed.get_backend_name() == "postgresql":
            if "connect_timeout" not in parsed.query:
                connect_args["connect_timeout"] = 5  # a host that drops packets: a clear failure, not a hang
            if "client_encoding" not in parsed.query:
                # a database created with SQL_ASCII (initdb on a host without a UTF-8 locale) hands text back as
                # bytes unless the connection asks for UTF-8: SQLAlchemy's first connect died on it
                connect_args["client_encoding"] = "utf8"
        created = create_engine(url, connect_args=connect_args, pool_pre_ping=True)
        if parsed.get_backend_name() == "sqlite":
            event.listen(created, "connect", _sqlite_foreign_keys)
        _engines[url] = created
        return created


def _private_file(path: Path) -> None:
    """Make a new SQLite file readable by this user only (it holds password hashes and the audit log); SQLite's
    journal files take the database file's mode."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileExistsError):
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))


def dispose(url: str | None = None) -> None:
    """Close the pooled connections of ``url``'s engine (tests call it before deleting a SQLite file)."""
    with _engines_lock:
        existing = _engines.pop(url or settings.database_url, None)
    if existing is not None:
        existing.dispose()


@contextmanager
def transaction(url: str | None = None) -> Iterator[Session]:
    """A session whose work is committed when the block ends and rolled back when it raises."""
    factory = sessionmaker(engine(url), expire_on_commit=False)
    with factory() as session, session.begin():
        yield session


def alembic_config(url: str | None = None) -> Config:
    """Programmatic Alembic configuration (no alembic.ini needed): the package's migrations, this URL."""
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("sqlalchemy.url", (url or settings.database_url).replace("%", "%%"))
    return config


def upgrade_to_head(url: str | None = None, *, attempts: int = 3) -> None:
    """Bring the database at ``url`` to the newest migration (creates a SQLite file if it is missing).

    Two servers (or test runs) starting at once on one SQLite file can race to create the first tables; the
    loser's transaction fails and is rolled back, and the retry finds the schema current.
    """
    target = engine(url)
    for attempt in range(1, attempts + 1):
        try:
            with _upgrade_lock, target.begin() as connection:  # Alembic loads env.py as a module: one at a time
                if connection.dialect.name == "postgresql":
                    # Servers sharing one PostgreSQL database upgrade one after the other (held to commit); the
                    # second then finds the schema current. SQLite locks the whole file on the first write instead.
                    connection.exec_driver_sql(f"SELECT pg_advisory_xact_lock({_UPGRADE_LOCK_KEY})")
                if _refuse_unknown_schema(connection) != carried_revisions().heads:
                    from alembic import command

                    config = alembic_config(url)
                    config.attributes["connection"] = connection
                    command.upgrade(config, "head")  # a schema at head: nothing to run (Alembic not even imported)
            return
        except OperationalError:
            if attempt == attempts:
                raise
            time.sleep(0.2 * attempt)


TOO_NEW = N_("The database schema is at revision {revision}, which this release ({version}) does not know: a newer "
             "release has upgraded the database. This release leaves it alone.")
TOO_NEW_HINT = N_("Run the release that upgraded the database (or a newer one), or restore the backup taken before "
                  "the upgrade.")


@dataclass(frozen=True)
class Revisions:
    known: frozenset[str]
    heads: frozenset[str]


REVISION_NAMES = ("revision", "down_revision")


@functools.cache
def carried_revisions() -> Revisions:
    """The migrations this release carries: every revision and the heads, read once per process from the
    ``revision`` and ``down_revision`` assignments of ``migrations/versions/*.py`` (Alembic would import itself and
    execute every migration file for them: ~0.2 s of each start; tests/services/test_database.py checks that this
    reading is Alembic's)."""
    known: set[str] = set()
    below: set[str] = set()
    for path in sorted((MIGRATIONS_DIR / "versions").glob("*.py")):
        values = _assigned(path, REVISION_NAMES)
        revision = values.get("revision")
        if not isinstance(revision, str):
            continue  # not a migration (__init__.py)
        known.add(revision)
        down = values.get("down_revision")
        below.update(down if isinstance(down, tuple | list) else [down] if isinstance(down, str) else [])
    return Revisions(frozenset(known), frozenset(known - below))


def _assigned(path: Path, names: tuple[str, ...]) -> dict[str, object]:
    """The literal values a module assigns to ``names`` at its top level."""
    values: dict[str, object] = {}
    for statement in ast.parse(path.read_text(encoding="utf-8")).body:
        target = (statement.targets[0] if isinstance(statement, ast.Assign) and len(statement.targets) == 1
                  else statement.target if isinstance(statement, ast.AnnAssign) else None)
        value = getattr(statement, "value", None)
        if isinstance(target, ast.Name) and target.id in names and value is not None:
            values[target.id] = ast.literal_eval(value)
    return values


def current_heads(connection: Connection) -> frozenset[str]:
    """The revisions the database is at (Alembic's version table; none before the first migration)."""
    if not inspect(connection).has_table("alembic_version"):
        return frozenset()
    return frozenset(str(row[0]) for row in connection.execute(text("SELECT version_num FROM alembic_version")))


def _refuse_unknown_schema(connection: Connection) -> frozenset[str]:
    """The database's current revisions, after refusing one this release does not know (a newer release's)."""
    from drivebench import __version__

    current = current_heads(connection)
    for revision in current - carried_revisions().known:
        raise SchemaTooNew(Text(TOO_NEW, revision=revision, version=__version__), hint=TOO_NEW_HINT)
    return current


def head_revision() -> str | None:
    """The newest migration this release carries."""
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config()).get_current_head()


def check_schema(url: str | None = None) -> str | None:
    """The database's revision (None: no tables yet); SchemaTooNew when a newer release has upgraded it."""
    with engine(url).connect() as connection:
        _refuse_unknown_schema(connection)
    return current_revision(url)


def current_revision(url: str | None = None) -> str | None:
    from alembic.runtime.migration import MigrationContext

    with engine(url).connect() as connection:
        return MigrationContext.configure(connection).get_current_revision()
