"""The audit log: every write the tool sends to a device, in the database, so it survives a restart.

A row is committed *before* the write is sent (result ``sending``) and completed with the outcome after it, so a
server that is killed mid-write still leaves a row saying a write to that parameter was under way. Who wrote and
why (a single write on the Parameters tab, ``download 12``, ``rollback 13``) come from the write's context
(:class:`~drivebench.services.params.write_context.WriteContext`: ``user`` and ``origin``).
"""

from __future__ import annotations

import asyncio
import csv
import io
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import or_, select, update

from drivebench.errors import DriveBenchError, SdoAbortError, WriteOutcomeUnknown
from drivebench.i18n import N_, Text
from drivebench.services.params import reads
from drivebench.services.params.values import WriteResult
from drivebench.services.params.write_context import LOCAL_USER
from drivebench.services.params.write_ports import WriteAttempt
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import AuditRow, utcnow

__all__ = [
    "CSV_COLUMNS",
    "LOCAL_USER",
    "AuditEntry",
    "AuditLog",
    "entries",
    "entry",
    "outcome",
    "to_csv",
]


@dataclass(frozen=True)
class AuditEntry:
    id: int
    time: datetime
    user: str
    session_id: str
    node_id: int
    ref: str
    address: str
    old_value: str | None
    new_value: str
    result: str
    detail: str | None
    origin: str
    profile: str | None = None
    """The profile the node was handled with when the write was sent."""


def _entry(row: AuditRow) -> AuditEntry:
    return AuditEntry(row.id, row.time, row.user, row.session_id, row.node_id, row.ref, row.address, row.old_value,
                      row.new_value, row.result, row.detail, row.origin, row.profile)


def entry(entry_id: int, url: str | None = None) -> AuditEntry | None:
    """One record by its id, None if there is none."""
    with transaction(url) as db:
        row = db.get(AuditRow, entry_id)
        return None if row is None else _entry(row)


def outcome(result: WriteResult | None, error: BaseException | None) -> tuple[str, str | None]:
    """(result, detail) as the log and the download report name them."""
    if error is not None:
        if isinstance(error, WriteOutcomeUnknown):
            return "unknown", error.detail
        if isinstance(error, SdoAbortError):
            return "failed", f"SDO abort 0x{error.abort_code:08X} {error.abort_text}"
        if isinstance(error, DriveBenchError):
            return "failed", error.detail
        if isinstance(error, asyncio.CancelledError):
            return "failed", Text(N_("cancelled while the write was under way: the device may hold either value"))
        return "failed", f"{type(error).__name__}: {error}"
    assert result is not None
    if result.verified is None:
        return "not verified", Text(N_("not read back"))
    if not result.verified:
        return "mismatch", result.mismatch
    return "written", Text(N_("takes effect after reset node")) if result.reset_required else None


class AuditLog:
    """The :class:`~drivebench.services.params.write_ports.WriteAudit` that stores rows (``url``: None =
    settings'); a server hands it to its session manager, which gives it to every session it opens."""

    def __init__(self, url: str | None = None) -> None:
        self.url = url

    async def sending(self, attempt: WriteAttempt) -> object:
        item = attempt.item
        profile = attempt.session.nodes[attempt.node_id].profile if attempt.node_id in attempt.session.nodes else None
        row = AuditRow(time=utcnow(), user=attempt.ctx.user, session_id=attempt.session.id,
                       node_id=attempt.node_id, ref=item.ref, address=item.address,
                       old_value=attempt.old.display if attempt.old else None,
                       new_value=reads.display(item, attempt.new), result="sending", origin=attempt.ctx.origin,
                       profile=profile.id if profile is not None else None)
        return await asyncio.to_thread(self._insert, row)

    async def done(self, token: object, result: WriteResult | None, error: BaseException | None) -> None:
        state, detail = outcome(result, error)
        await asyncio.to_thread(self._complete, int(token), state,  # type: ignore[call-overload]
                                None if detail is None else str(detail))

    def _insert(self, row: AuditRow) -> int:
        with transaction(self.url) as db:
            db.add(row)
            db.flush()
            return row.id

    def _complete(self, row_id: int, state: str, detail: str | None) -> None:
        with transaction(self.url) as db:
            db.execute(update(AuditRow).where(AuditRow.id == row_id).values(result=state, detail=detail))


def entries(url: str | None = None, *, node_id: int | None = None, session_id: str | None = None,
            query: str = "", origin: str | None = None, limit: int = 1000) -> list[AuditEntry]:
    """Newest first."""
    statement = select(AuditRow).order_by(AuditRow.id.desc()).limit(limit)
    if node_id is not None:
        statement = statement.where(AuditRow.node_id == node_id)
    if session_id:
        statement = statement.where(AuditRow.session_id == session_id)
    if origin:
        statement = statement.where(AuditRow.origin == origin)
    if query.strip():
        pattern = f"%{query.strip()}%"
        statement = statement.where(or_(AuditRow.ref.ilike(pattern), AuditRow.user.ilike(pattern),
                                        AuditRow.result.ilike(pattern), AuditRow.origin.ilike(pattern)))
    with transaction(url) as db:
        return [_entry(row) for row in db.scalars(statement)]


CSV_COLUMNS = ["time", "user", "session", "node", "parameter", "address", "old value", "new value", "result",
               "detail", "origin"]


def to_csv(found: list[AuditEntry]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for e in found:
        writer.writerow([e.time.isoformat(timespec="milliseconds"), e.user, e.session_id, e.node_id, e.ref,
                         e.address, e.old_value or "", e.new_value, e.result, e.detail or "", e.origin])
    return out.getvalue()
