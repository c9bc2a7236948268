"""Who sends a write and from which screen, as the audit log names them: context variables the caller sets
(:func:`acting`) and every write inside carries, whatever service sends it (parameters, PDO mapping, heartbeat,
the control panel)."""

from __future__ import annotations

import contextlib
import getpass
from collections.abc import Iterator
from contextvars import ContextVar


def _local_user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (containers)
        return "local"


LOCAL_USER = _local_user()
current_user: ContextVar[str] = ContextVar("drivebench_user", default=LOCAL_USER)
current_origin: ContextVar[str] = ContextVar("drivebench_write_origin", default="parameters")


@contextlib.contextmanager
def acting(origin: str, user: str | None = None) -> Iterator[None]:
    """Writes inside the block are logged with this origin (and user)."""
    origin_token = current_origin.set(origin)
    user_token = current_user.set(user) if user else None
    try:
        yield
    finally:
        current_origin.reset(origin_token)
        if user_token is not None:
            current_user.reset(user_token)
