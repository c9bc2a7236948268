"""The Node page's PDO tab: every RPDO/TPDO as the device holds it, the mapping editor, apply with its step
report, RPDO sending and the SYNC producer. Blocks of ``node/pdo.html``; live values come over
``/ws/sessions/{session}/nodes/{node}/process-data``.

RPDO sends and NMT start need the ``confirm`` field naming the node (the forms carry it, after the browser's
confirmation) and arm the node for this tab: its keep-alive socket must stay open or the node is stopped.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from typing import Annotated, Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, Response
from markupsafe import Markup
from pydantic import BaseModel

from drivebench.device.profiles import pdo_notes
from drivebench.errors import AccessDenied, InvalidValue
from drivebench.i18n import _
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.bus.views import node_public
from drivebench.services.control import drive_guard
from drivebench.services.monitoring.diagnostics import nmt_state_text
from drivebench.services.pdos import ethercat_pdo, pdo
from drivebench.services.pdos import process_data as live
from drivebench.services.pdos.pdo import ApplyReport, Direction, PdoConfig, PdoWrite
from drivebench.services.users.principals import Role
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.identity import principal_of
from drivebench.web.problems import status_for
from drivebench.web.safety import PanelDep, WriteCtxDep, confirmation
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
log = logging.getLogger(__name__)
UI = "/ui/sessions/{session_id}/nodes/{node_id}/pdo"


def _model_json(items: Sequence[BaseModel]) -> str:
    return json.dumps([item.model_dump(mode="json") for item in items])


templates.env.filters["model_json"] = _model_json


def _context(session: Session, node: SessionNode, **extra: Any) -> dict[str, Any]:
    base = f"/ui/sessions/{session.id}/nodes/{node.node_id}"
    return {"session": session, "node": node, "base": base, "public": node_public(session, node),
            "api": f"/api/sessions/{session.id}/nodes/{node.node_id}/pdos",
            "sync_period_ms": live.service(session).sync_period_ms, **extra}


def _card_context(session: Session, node: SessionNode, config: PdoConfig) -> dict[str, Any]:
    profile = node.profile
    type_notes = {} if profile is None else {
        t: note for t in range(256) if (note := pdo_notes.transmission_note(profile, config.direction, t))}
    return {"pdo": config, "mappable": pdo.mappable_objects(session, node.node_id, config.direction),
            "type_notes": type_notes}


def _ecat_context(session: Session, node: SessionNode, assignment: ethercat_pdo.EcatAssignment) -> dict[str, Any]:
    return {"assignment": assignment, "mappable": pdo.mappable_objects(session, node.node_id, assignment.direction)}


def _parse_entries(text: str) -> list[tuple[int, int]]:
    entries = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        try:
            index, sub = part.split(".")
            entries.append((int(index, 16), int(sub)))
        except ValueError as exc:
            raise InvalidValue(_("'{entry}' is not a mapping entry (expected index.sub like 0x6040.0)").format(
                entry=part)) from exc
    return entries


@router.get(UI, response_class=HTMLResponse)
async def pdo_list(request: Request, session: SessionDep, node: NodeDep) -> Response:
    profile = node.profile
    if not session.network.capabilities.frames:  # EtherCAT: assignment 0x1C12/0x1C13 and the mappings, no COB-IDs
        cards = []
        assignments = [_ecat_context(session, node, a) for a in
                       await ethercat_pdo.read_assignments(session, node.node_id)]
    else:
        cards = [_card_context(session, node, c) for c in await live.service(session).load(node.node_id)]
        assignments = []
    context = _context(session, node, cards=cards, assignments=assignments,
                       device_notes=pdo_notes.device_notes(profile) if profile else [])
    return templates.TemplateResponse(request, "node/pdo.html", context, block_name="pdo_list")


@router.post(UI + "/{direction}/{number}/apply", response_class=HTMLResponse)
async def apply(request: Request, session: SessionDep, node: NodeDep, direction: Direction, number: int,
                ctx: WriteCtxDep, entries: Annotated[str, Form()] = "", cob_id: Annotated[str, Form()] = "",
                valid: Annotated[str, Form()] = "", transmission_type: Annotated[str, Form()] = "",
                inhibit_time_ms: Annotated[str, Form()] = "", event_timer_ms: Annotated[str, Form()] = "") -> Response:
    try:
        write = PdoWrite(entries=_parse_entries(entries), valid=bool(valid),
                         cob_id=int(cob_id, 16) if cob_id.strip() else None,
                         transmission_type=int(transmission_type) if transmission_type.strip() else None,
                         inhibit_time_ms=float(inhibit_time_ms) if inhibit_time_ms.strip() else None,
                         event_timer_ms=int(event_timer_ms) if event_timer_ms.strip() else None)
    except ValueError as exc:
        raise InvalidValue(_("{pdo}: {problem}").format(pdo=f"{direction.upper()}{number}", problem=exc)) from exc
    report: ApplyReport = await pdo.apply_pdo(session, node.node_id, direction, number, write, ctx=ctx)
    await live.service(session).load(node.node_id)
    config = report.pdo or await pdo.read_pdo(session, node.node_id, direction, number)
    context = _context(session, node, report=report, **_card_context(session, node, config))
    response = templates.TemplateResponse(request, "node/_pdo_card.html", context,
                                          status_code=200 if report.ok else 502)
    response.headers["X-PDO-Report"] = "ok" if report.ok else "failed"  # pdo.js swaps a failed report in too
    return response


@router.post(UI + "/ethercat/{direction}/{number}/apply", response_class=HTMLResponse)
async def apply_ethercat(request: Request, session: SessionDep, node: NodeDep, direction: Direction, number: int,
                         ctx: WriteCtxDep, entries: Annotated[str, Form()] = "") -> Response:
    try:
        report = await ethercat_pdo.apply_mapping(session, node.node_id, direction, number, _parse_entries(entries),
                                                  ctx=ctx)
        status = 200
    except ethercat_pdo.MappingNotApplied as exc:  # the card shows the step report, with the problem's status
        report, status = exc.report, status_for(exc)
    mapped = report.pdo or await ethercat_pdo.read_mapping_object(session, node.node_id, direction, number)
    context = _context(session, node, report=report, ecat_pdo=mapped,
                       mappable=pdo.mappable_objects(session, node.node_id, direction))
    return templates.TemplateResponse(request, "node/_ecat_pdo_card.html", context, status_code=status)


@router.post(UI + "/rpdo/{number}/send", response_class=HTMLResponse)
async def send(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep, ctx: WriteCtxDep,
               number: int) -> Response:
    form = await request.form()
    values = {key[2:]: str(value) for key, value in form.items() if key.startswith("v:")}
    mode, owner = str(form.get("mode", "once")), str(form.get("client_id", ""))
    confirm = confirmation(request, form.get("confirm") or None, str(form.get("confirm_values") or "") or None)
    keepalive = str(form.get("keepalive", "true")).lower() != "false"
    if not keepalive:  # a script that keeps its own watch: admins only, with a reason (logged)
        principal = principal_of(request)
        if not principal.may(Role.ADMIN):
            raise AccessDenied(_("Sending RPDOs without the keep-alive guard is for admins only."))
        if not str(form.get("reason") or "").strip():
            raise InvalidValue(_("Say why the RPDO is sent without the keep-alive guard (reason)."))
        log.warning("RPDO%s to node %s sent without keep-alive by %s: %s", number, node.node_id, principal.name,
                    form.get("reason"))
    if mode == "cyclic":
        try:
            period_ms = int(str(form.get("period_ms") or "100"))
        except ValueError as exc:
            raise InvalidValue(_("The cycle time is a whole number of milliseconds.")) from exc
        data = await drive_guard.send_rpdo(session, node.node_id, number, values, panel, ctx=ctx, confirm=confirm,
                                           owner=owner,
                                           period_ms=period_ms, keepalive=keepalive)
        message = _("sending every {time} ms").format(time=period_ms)
    else:
        data = await drive_guard.send_rpdo(session, node.node_id, number, values, panel, ctx=ctx, confirm=confirm,
                                           keepalive=keepalive)
        message = _("sent once")
    state, _live = session.nmt_state(node.node_id)
    commanded = node.commanded_state.label if node.commanded_state is not None else ""
    if "Operational" not in (state, commanded):  # CiA 301: PDOs are processed only in Operational
        # (a start just sent counts: the next heartbeat will confirm it)
        message += _(" - node {node} is {state}: it ignores PDOs until it is started").format(
            node=node.node_id, state=nmt_state_text(state))
    context = _context(session, node, sent=f"{message}: {data.hex(' ').upper() or _('(no data)')}", number=number,
                       cyclic=mode == "cyclic")
    return templates.TemplateResponse(request, "node/_pdo_card.html", context, block_name="send_result")


@router.post(UI + "/rpdo/{number}/stop", response_class=HTMLResponse)
async def stop(request: Request, session: SessionDep, node: NodeDep, number: int,
               client_id: Annotated[str, Form()] = "") -> Response:
    service = live.service(session)
    layout = service.layout(node.node_id, "rpdo", number)
    stopped = service.stop_cyclic(client_id, layout.config.cob_id)
    context = _context(session, node, sent=_("cyclic sending stopped") if stopped else _("was not sending"),
                       number=number, cyclic=False)
    return templates.TemplateResponse(request, "node/_pdo_card.html", context, block_name="send_result")


@router.post(UI + "/sync", response_class=HTMLResponse)
async def sync(request: Request, session: SessionDep, node: NodeDep, period_ms: Annotated[int, Form()] = 100,
               on: Annotated[str, Form()] = "") -> Response:
    service = live.service(session)
    if on:
        service.start_sync(period_ms)
    else:
        service.stop_sync()
    return templates.TemplateResponse(request, "node/pdo.html", _context(session, node), block_name="sync_form")


@router.post(UI + "/start-node", response_class=HTMLResponse)
async def start_node(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep, ctx: WriteCtxDep,
                     confirm: Annotated[str, Form()] = "", confirm_values: Annotated[str, Form()] = "") -> Response:
    await drive_guard.nmt(session, NmtCommand.START, node.node_id, panel, ctx=ctx,
                          confirm=confirmation(request, confirm or None, confirm_values or None))
    return HTMLResponse(Markup('<span class="pdo-sent">{}</span>').format(
        _("NMT start sent to node {node}: this tab keeps it running (closing it stops the node)").format(
            node=node.node_id)))
