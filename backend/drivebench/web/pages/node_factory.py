"""The Parameters tab's comparison with the factory setting and its list of writes to the node with undo (issue 30
item 5). Blocks of ``node/factory.html``; the work is done by :mod:`services.params.factory_compare` and
:mod:`services.users.undo`."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Form, Query, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.config import settings
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.number_base import shows_hex
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import factory_compare, lookup, session_part
from drivebench.services.users import audit, undo
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.pages.node import UI
from drivebench.web.safety import WriteCtxDep, confirmation
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
WRITES_SHOWN = 30


def radix_switch(item: Item) -> bool:
    """The row offers the hex/decimal switch: a plain integer (no selection, no scaling)."""
    entry = item.entry
    return entry.data_type.is_integer and entry.data_type.size is not None and not entry.selection \
        and entry.factor == 1 and entry.data_type.value != "BOOLEAN"


templates.env.filters["factory_value"] = factory_compare.factory_value
templates.env.filters["radix_switch"] = radix_switch
templates.env.filters["shows_hex"] = shows_hex


def _context(session: Session, node: SessionNode, **extra: Any) -> dict[str, Any]:
    return {"session": session, "node": node, "base": f"/ui/sessions/{session.id}/nodes/{node.node_id}", **extra}


@router.get(UI + "/changed-from-default", response_class=HTMLResponse)
async def changed_from_default(request: Request, session: SessionDep, node: NodeDep,
                               read: Annotated[factory_compare.Reading, Query()] = factory_compare.Reading.ALL,
                               ) -> Response:
    found = await factory_compare.compare(session, node.node_id, read)
    return templates.TemplateResponse(request, "node/factory.html", _context(session, node, comparison=found),
                                      block_name="comparison")


def _writes(request: Request, session: Session, node: SessionNode, **extra: Any) -> Response:
    found = audit.entries(settings.database_url, node_id=node.node_id, session_id=session.id, limit=WRITES_SHOWN)
    refusals = {entry.id: undo.refusal(session, entry) for entry in found}
    context = _context(session, node, writes=found, refusals=refusals, **extra)
    return templates.TemplateResponse(request, "node/factory.html", context, block_name="writes")


@router.get(UI + "/writes", response_class=HTMLResponse)
async def writes(request: Request, session: SessionDep, node: NodeDep) -> Response:
    return _writes(request, session, node)


@router.post(UI + "/undo/{entry_id}", response_class=HTMLResponse)
async def undo_write(request: Request, session: SessionDep, node: NodeDep, entry_id: int, ctx: WriteCtxDep,
                     confirm: Annotated[str | None, Form()] = None,
                     confirm_values: Annotated[str | None, Form()] = None) -> Response:
    """Undo one write of this node; an old value that can move the drive is asked first (data-asks-moving)."""
    record = undo.record(entry_id, settings.database_url)
    result = await undo.undo(session, record,
                             ctx=ctx.confirming(confirmation(request, confirm or None, confirm_values or None)))
    item = lookup.resolve(node, record.ref)
    return _writes(request, session, node, undone=record, result=result, item=item,
                   values=session_part.service(session).values.get(node.node_id, {}),
                   failures=session_part.service(session).failures.get(node.node_id, {}))
