"""The server's log: one line per record with time (UTC), level, logger and the request it belongs to; JSON lines
with ``DRIVEBENCH_LOG_FORMAT=json`` (for a plant's log collector), the level from ``DRIVEBENCH_LOG_LEVEL``.

The request id comes from the request's ``X-Request-ID`` (a proxy's) or is made up (web/request_ids.py); records
outside a request carry ``-``. Uvicorn's own and access records go through the same handler."""

from __future__ import annotations

import json
import logging
import sys
from contextvars import ContextVar
from datetime import UTC, datetime
from typing import Any, TextIO

request_id: ContextVar[str] = ContextVar("drivebench_request_id", default="-")

LEVELS = ("critical", "error", "warning", "info", "debug")
FORMATS = ("text", "json")
TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s [%(request_id)s] %(message)s"


class RequestIdFilter(logging.Filter):
    """Puts the request id of the running request on every record."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.request_id = request_id.get()
        return True


class UtcFormatter(logging.Formatter):
    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
        return datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds")


class JsonFormatter(UtcFormatter):
    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, object] = {"time": self.formatTime(record), "level": record.levelname,
                                    "logger": record.name, "request_id": getattr(record, "request_id", "-"),
                                    "message": record.getMessage()}
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, ensure_ascii=False)


class StderrHandler(logging.StreamHandler):
    """Writes to ``sys.stderr`` as it is when a record comes (a server run inside another program, such as a test
    that captures its output, must not keep writing to a stream that was closed since)."""

    def __init__(self) -> None:
        super().__init__()

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, _value: object) -> None:
        pass


def log_config(level: str, form: str) -> dict[str, Any]:
    """A :func:`logging.config.dictConfig` for the server (uvicorn takes it as ``log_config``)."""
    formatter: dict[str, Any] = ({"()": JsonFormatter} if form == "json"
                                 else {"()": UtcFormatter, "format": TEXT_FORMAT})
    handler = {"()": StderrHandler, "formatter": "server",
               "filters": ["request_id"]}
    loud = level.upper()
    return {
        "version": 1, "disable_existing_loggers": False,
        "filters": {"request_id": {"()": RequestIdFilter}},
        "formatters": {"server": formatter},
        "handlers": {"server": handler},
        "root": {"handlers": ["server"], "level": loud},
        "loggers": {**{name: {"handlers": [], "level": loud, "propagate": True}
                       for name in ("uvicorn", "uvicorn.error", "uvicorn.access")},
                    # the migration tool's chatter ("Context impl SQLiteImpl.") only when debugging
                    "alembic": {"handlers": [], "level": loud if loud == "DEBUG" else "WARNING", "propagate": True}},
    }
