"""Whether the database answers, and when it does not, what failed in words: which host, refused, authentication,
name not resolved, no answer, and what to check. The password of the URL is never part of a message."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from sqlalchemy import text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError, SQLAlchemyError

from drivebench.config import settings
from drivebench.errors import DatabaseUnavailable
from drivebench.i18n import N_, Text
from drivebench.services.storage.database import engine

REFUSED = N_("{where} refused the connection: nothing listens there.")
REFUSED_HINT = N_("Check that PostgreSQL runs on that host and port and that no firewall is in the way.")
AUTHENTICATION = N_("{where} did not accept the user {user}: authentication failed.")
AUTHENTICATION_HINT = N_("Check the user name and the password in DRIVEBENCH_DATABASE_URL, and that the "
                         "database server lets this user in from this machine (pg_hba.conf).")
UNRESOLVED = N_("The database host name {host} could not be resolved.")
UNRESOLVED_HINT = N_("Check the host name in DRIVEBENCH_DATABASE_URL and this machine's name service (DNS, "
                     "/etc/hosts; in a container: the service name in the compose file).")
NO_DATABASE = N_("{where} has no database {database}.")
NO_DATABASE_HINT = N_("Create it (createdb {database}) or correct the database name in DRIVEBENCH_DATABASE_URL.")
NO_ANSWER = N_("{where} did not answer in time.")
NO_ANSWER_HINT = N_("Check that the host is up and reachable from this machine on that port.")
SQLITE_FILE = N_("The SQLite database file {file} cannot be opened.")
SQLITE_HINT = N_("Check that its folder exists and that the user the server runs as may write there.")
OTHER = N_("{where} cannot be used: {reason}")
OTHER_HINT = N_("Check DRIVEBENCH_DATABASE_URL and the database server's log.")

_KINDS: list[tuple[tuple[str, ...], str, str]] = [
    (("connection refused",), REFUSED, REFUSED_HINT),
    (("password authentication failed", "authentication failed", "no password supplied", "role \""),
     AUTHENTICATION, AUTHENTICATION_HINT),
    (("could not translate host name", "name or service not known", "failed to resolve host",
      "temporary failure in name resolution", "nodename nor servname"), UNRESOLVED, UNRESOLVED_HINT),
    (("does not exist",), NO_DATABASE, NO_DATABASE_HINT),
    (("timeout expired", "timed out"), NO_ANSWER, NO_ANSWER_HINT),
    (("unable to open database file",), SQLITE_FILE, SQLITE_HINT),
]


def unavailable(exc: BaseException, url: str | None = None) -> DatabaseUnavailable:
    """The database error ``exc`` (a SQLAlchemy or driver error) as a problem in words."""
    parsed = make_url(url or settings.database_url)
    where = f"{parsed.host or 'localhost'}:{parsed.port or 5432}"
    values = {"where": Text(N_("The database server at {address}"), address=where), "host": parsed.host or "",
              "user": parsed.username or "", "database": parsed.database or "", "file": parsed.database or ""}
    original = exc.orig if isinstance(exc, DBAPIError) and exc.orig is not None else exc
    message = str(original).strip()
    lowered = message.lower()
    for needles, template, hint in _KINDS:
        if any(needle in lowered for needle in needles):
            return DatabaseUnavailable(Text(template, **values), hint=Text(hint, database=values["database"]))
    reason = message.splitlines()[0] if message else type(original).__name__
    return DatabaseUnavailable(Text(OTHER, where=values["where"], reason=reason), hint=OTHER_HINT)


def probe(url: str | None = None) -> DatabaseUnavailable | None:
    """None when the database answers a query now; else what failed."""
    try:
        with engine(url).connect() as connection:
            connection.execute(text("SELECT 1"))
    except SQLAlchemyError as exc:
        return unavailable(exc, url)
    return None


class RecentProbes:
    """The database's answer to :func:`probe`, asked at most every ``every_s`` per URL and one query at a time
    (monitors poll the health check once a second, or more). A web app holds one (``web/state.AppState``)."""

    def __init__(self, every_s: float = 2.0) -> None:
        self.every_s = every_s
        self._known: dict[str, tuple[float, DatabaseUnavailable | None]] = {}
        self._lock = threading.Lock()

    def recent(self, url: str) -> tuple[bool, DatabaseUnavailable | None]:
        """Whether the last answer is at most ``every_s`` old, and that answer (None: it answered), asking nothing."""
        at, failure = self._known.get(url, (-self.every_s, None))
        return time.monotonic() - at < self.every_s, failure

    def failure(self, url: str) -> DatabaseUnavailable | None:
        """The last answer, the database asked again when it is older than ``every_s`` (blocking)."""
        with self._lock:
            fresh, failure = self.recent(url)
            if not fresh:
                failure = probe(url)
                self._known[url] = (time.monotonic(), failure)
            return failure


def wait_for_database(url: str | None = None, *, wait_s: float | None = None,
                      report: Callable[[DatabaseUnavailable], None] | None = None) -> None:
    """Return once the database answers; try again every second for ``wait_s`` (``settings.database_wait_s``),
    then raise what failed last. ``report`` hears the first failure (so a log says why the start waits)."""
    deadline = time.monotonic() + (settings.database_wait_s if wait_s is None else wait_s)
    reported = False
    while (failure := probe(url)) is not None:
        if report is not None and not reported:
            report(failure)
            reported = True
        if time.monotonic() >= deadline:
            raise failure
        time.sleep(max(0.0, min(1.0, deadline - time.monotonic())))
