"""Each configuring LSS step in the audit log: one row (node ID 0 for a step that reaches every device)."""

from __future__ import annotations

import asyncio

from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import AuditRow, utcnow

ORIGIN = "lss"


def _insert(row: AuditRow) -> None:
    with transaction(None) as db:
        db.add(row)


async def record(session_id: str, user: str, node_id: int, step: str, value: str, error: str | None) -> None:
    row = AuditRow(time=utcnow(), user=user, session_id=session_id, node_id=node_id, ref="LSS", address="0x7E5",
                   old_value=None, new_value=f"{step}: {value}"[:2000], result="failed" if error else "written",
                   detail=error, origin=ORIGIN, profile=None)
    await asyncio.to_thread(_insert, row)
