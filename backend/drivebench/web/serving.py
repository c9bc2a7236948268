"""How ``drivebench serve`` runs uvicorn: its own timeouts and limits, and a guard for what uvicorn lacks.

uvicorn closes an idle keep-alive connection (``timeout_keep_alive``) and answers 503 past ``limit_concurrency``,
but it gives a connection unlimited time to send its request headers, and it holds every connection it accepts: 3,000
clients trickling one header line every few seconds stayed open for minutes, and some 20,000 used up the open-file
limit so that even ``/api/health`` was refused (issue 28 item 14). The protocol classes here add both:

* a header deadline: a connection that has not sent a request's complete headers ``HEADER_TIMEOUT_S`` after it
  opened (or after its previous answer) is closed;
* a connection limit: at ``max_connections`` a new connection sheds the one that has waited longest for its
  headers (a connection whose request is under way is never shed); when none waits, the new one is closed.

The access log (``--log-level info``) shows a share link's or an API token's first characters, never the whole
token: a request line such as ``GET /remote/dbv_…`` would otherwise hand a log reader the link.
"""

from __future__ import annotations

import asyncio
import importlib.util
import logging
import re
import resource
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

from drivebench import logs

HEADER_TIMEOUT_S = 10.0
KEEP_ALIVE_S = 5
MAX_HEADER_BYTES = 16 * 1024
MOST_CONNECTIONS = 4000


class _HeaderGuard:
    """Mixed into uvicorn's HTTP protocol classes (see the module's docstring)."""

    header_timeout_s = HEADER_TIMEOUT_S
    max_connections = MOST_CONNECTIONS
    connections: set[Any]
    loop: asyncio.AbstractEventLoop
    transport: asyncio.Transport
    _deadline: asyncio.TimerHandle | None = None
    waiting_since: float | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)  # type: ignore[misc]
        if len(self.connections) > self.max_connections and not self._shed_one():
            self.transport.close()
            return
        self._await_headers()

    def connection_lost(self, exc: Exception | None) -> None:
        self._headers_in()
        super().connection_lost(exc)  # type: ignore[misc]

    def on_response_complete(self) -> None:
        super().on_response_complete()  # type: ignore[misc]
        if not self.transport.is_closing() and not getattr(self, "pipeline", None):
            self._await_headers()  # the next request's headers, on a kept-alive connection (none are queued)

    def _await_headers(self) -> None:
        self._headers_in()
        self.waiting_since = self.loop.time()
        self._deadline = self.loop.call_later(self.header_timeout_s, self._too_slow)

    def _headers_in(self) -> None:
        self.waiting_since = None
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _too_slow(self) -> None:
        self._deadline = None
        if not self.transport.is_closing():
            self.transport.close()

    def _shed_one(self) -> bool:
        waiting = [c for c in self.connections if c is not self and getattr(c, "waiting_since", None) is not None]
        if not waiting:
            return False
        oldest = min(waiting, key=lambda c: c.waiting_since)
        oldest._headers_in()
        oldest.transport.close()
        return True


class GuardedH11(_HeaderGuard, H11Protocol):
    def handle_events(self) -> None:
        cycle = self.cycle
        super().handle_events()
        if self.cycle is not cycle:  # a request's headers arrived
            self._headers_in()


def _httptools_class() -> type[Any] | None:
    if importlib.util.find_spec("httptools") is None:
        return None
    from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

    class GuardedHttpTools(_HeaderGuard, HttpToolsProtocol):
        def on_headers_complete(self) -> None:
            self._headers_in()
            super().on_headers_complete()

    return GuardedHttpTools


def max_connections() -> int:
    """Half the process's open-file limit (the rest: the database, bus adapters, log files), at most 4000."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    return max(32, min(MOST_CONNECTIONS, soft // 2 if soft != resource.RLIM_INFINITY else MOST_CONNECTIONS))


def uvicorn_options(*, header_timeout_s: float = HEADER_TIMEOUT_S, connections: int | None = None,
                    log_level: str = "info", log_format: str = "text") -> dict[str, Any]:
    """The uvicorn settings of ``drivebench serve`` (tests serve with them too)."""
    most = connections or max_connections()
    protocol = _httptools_class() or GuardedH11
    guarded = type(protocol.__name__, (protocol,), {"header_timeout_s": header_timeout_s, "max_connections": most})
    return {"http": guarded, "timeout_keep_alive": KEEP_ALIVE_S, "limit_concurrency": most + 16,
            "h11_max_incomplete_event_size": MAX_HEADER_BYTES,
            "log_config": log_config(log_level, log_format)}


_TOKEN = re.compile(r"\b(db[tv]_[A-Za-z0-9_-]{6})[A-Za-z0-9_-]+")


def without_tokens(text: str) -> str:
    """``/remote/dbv_abcdef…`` for ``/remote/dbv_abcdefghijk…``: the hint the Remote and Users pages show."""
    return _TOKEN.sub(r"\1…", text)


class TokenRedaction(logging.Filter):
    """Takes the tokens out of an access log record's arguments (the request line is made from them)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(without_tokens(arg) if isinstance(arg, str) else arg for arg in record.args)
        return True


def log_config(level: str = "info", form: str = "text") -> dict[str, Any]:
    """The server's logging set-up (drivebench/logs.py) with ``TokenRedaction`` on every record."""
    config = logs.log_config(level, form)
    config["filters"]["tokens"] = {"()": TokenRedaction}
    config["handlers"]["server"]["filters"].append("tokens")
    return config
