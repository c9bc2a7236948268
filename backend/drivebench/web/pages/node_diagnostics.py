"""The Diagnostics tab of the Node screen: health, heartbeat and guarding set-up, EMCY history, vendor values."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.errors import DriveBenchError
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.bus.views import node_public
from drivebench.services.monitoring import diagnostics, fault_words
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.safety import WriteCtxDep
from drivebench.web.templating import templates

# set-up writes take the node lease (WriteCtxDep)
router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
UI = "/ui/sessions/{session_id}/nodes/{node_id}/diagnostics"
PAGE = "node/diagnostics_body.html"


def _context(session: Session, node: SessionNode, **extra: Any) -> dict[str, Any]:
    return {"session": session, "node": node, "base": f"/ui/sessions/{session.id}/nodes/{node.node_id}",
            "health": diagnostics.node_health(session, node),
            "history": diagnostics.emcy_history(session, node.node_id),
            "groups": diagnostics.diagnostic_groups(node),
            "guarding_supported": bool(node.profile and node.profile.features.node_guarding),
            "has_faults": bool(node.profile and node.profile.faults),
            "slave": node_public(session, node) if session.network.capabilities.esm else None, **extra}


async def _setup(session: Session, node: SessionNode) -> dict[str, Any]:
    if not session.network.capabilities.heartbeat:  # EtherCAT: the master watches its slaves
        return {"setup": None, "setup_error": None}
    try:
        return {"setup": await diagnostics.read_heartbeat_setup(session, node.node_id), "setup_error": None}
    except DriveBenchError as exc:
        return {"setup": None, "setup_error": exc}


@router.get(UI, response_class=HTMLResponse)
async def diagnostics_tab(request: Request, session: SessionDep, node: NodeDep) -> Response:
    context = _context(session, node, **await _setup(session, node))
    return templates.TemplateResponse(request, PAGE, context)


@router.get(UI + "/health", response_class=HTMLResponse)
async def health_block(request: Request, session: SessionDep, node: NodeDep) -> Response:
    return templates.TemplateResponse(request, PAGE, _context(session, node), block_name="health_live")


@router.get(UI + "/faults", response_class=HTMLResponse)
async def faults_block(request: Request, session: SessionDep, node: NodeDep) -> Response:
    context = _context(session, node, faults=await fault_words.faults(session, node))
    return templates.TemplateResponse(request, PAGE, context, block_name="faults")


@router.get(UI + "/vendor", response_class=HTMLResponse)
async def vendor_block(request: Request, session: SessionDep, node: NodeDep) -> Response:
    values = await diagnostics.read_diagnostics(session, node.node_id)
    return templates.TemplateResponse(request, PAGE, _context(session, node, values=values), block_name="vendor")


@router.post(UI + "/producer", response_class=HTMLResponse)
async def set_producer(request: Request, session: SessionDep, node: NodeDep, ctx: WriteCtxDep,
                       time_ms: Annotated[int, Form(ge=0, le=65535)]) -> Response:
    setup = await diagnostics.write_heartbeat_producer(session, node.node_id, ctx, time_ms)
    context = _context(session, node, setup=setup, setup_error=None,
                       setup_ok=_("Heartbeat producer time {ms} ms written and read back.").format(ms=time_ms))
    return templates.TemplateResponse(request, PAGE, context, block_name="heartbeat")


@router.post(UI + "/consumers/{slot}", response_class=HTMLResponse)
async def set_consumer(request: Request, session: SessionDep, node: NodeDep, slot: int, ctx: WriteCtxDep,
                       producer_id: Annotated[int, Form(ge=0, le=127)],
                       time_ms: Annotated[int, Form(ge=0, le=65535)]) -> Response:
    setup = await diagnostics.write_heartbeat_consumer(session, node.node_id, ctx, slot, producer_id, time_ms)
    context = _context(session, node, setup=setup, setup_error=None,
                       setup_ok=_("Consumer entry {slot}: node {node}, {ms} ms written and read back.").format(
                           slot=slot, node=producer_id, ms=time_ms))
    return templates.TemplateResponse(request, PAGE, context, block_name="heartbeat")


@router.post(UI + "/guarding", response_class=HTMLResponse)
async def set_guarding(request: Request, session: SessionDep, node: NodeDep, ctx: WriteCtxDep,
                       guard_time_ms: Annotated[int, Form(ge=0, le=65535)],
                       life_time_factor: Annotated[int, Form(ge=0, le=255)]) -> Response:
    await diagnostics.start_guarding(session, node.node_id, ctx, guard_time_ms, life_time_factor)
    return templates.TemplateResponse(request, PAGE, _context(session, node), block_name="health")
