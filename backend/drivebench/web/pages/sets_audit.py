"""The Sets page's audit log: the filter and, per record, the undo the node's Parameters tab offers (issue 30
item 5): the record's old value written back through the checked write (:mod:`services.users.undo`, the service of
``POST /api/audit/{id}/undo``), a moving old value asked first (data-asks-moving), refusals said in words."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.config import settings
from drivebench.errors import DriveBenchError
from drivebench.i18n import _
from drivebench.services.session_manager import SessionManager
from drivebench.services.users import audit, undo
from drivebench.services.users.audit import AuditEntry
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import ManagerDep
from drivebench.web.safety import WriteCtxDep, confirmation
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)  # an undo takes the node lease (WriteCtxDep)
UI = "/parameter-sets"
SHOWN = 200


def refusals(manager: SessionManager, entries: list[AuditEntry]) -> dict[int, str | None]:
    """Why each record cannot be undone now (None: it can), as the Parameters tab says it."""
    found: dict[int, str | None] = {}
    for entry in entries:
        try:
            session = manager.get(entry.session_id)
        except DriveBenchError:
            found[entry.id] = _("Record {id}: session {session} is not open now; its old value cannot be written "
                                "back.").format(id=entry.id, session=entry.session_id)
            continue
        found[entry.id] = undo.refusal(session, entry)
    return found


def audit_context(manager: SessionManager, q: str = "") -> dict[str, Any]:
    entries = audit.entries(query=q, limit=SHOWN)
    return {"audit": entries, "audit_q": q, "refusals": refusals(manager, entries)}


def _block(request: Request, context: dict[str, Any]) -> Response:
    return templates.TemplateResponse(request, "sets.html", {"active": "sets", **context}, block_name="audit")


@router.get(UI + "/audit/rows", response_class=HTMLResponse)
async def audit_rows(request: Request, manager: ManagerDep, q: str = "") -> Response:
    return _block(request, audit_context(manager, q))


@router.post(UI + "/audit/{entry_id}/undo", response_class=HTMLResponse)
async def undo_write(request: Request, manager: ManagerDep, entry_id: int, ctx: WriteCtxDep, q: str = "",
                     confirm: Annotated[str | None, Form()] = None,
                     confirm_values: Annotated[str | None, Form()] = None) -> Response:
    """Undo one record; the log is shown again with the result (a write of its own, origin ``undo <id>``)."""
    record = undo.record(entry_id, settings.database_url)
    session = manager.get(record.session_id)
    ctx = ctx.confirming(confirmation(request, confirm or None, confirm_values or None))
    result = await undo.undo(session, record, ctx=ctx)
    return _block(request, {**audit_context(manager, q), "undone": record, "result": result})
