"""The Monitor screen: live counters, bus-load chart, trace, filters, recordings, device telegram counters."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Form, Query, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from drivebench.i18n import N_, ngettext
from drivebench.services.bus.sessions import Session
from drivebench.services.bus.views import NodePublic, nodes_public, session_public
from drivebench.services.monitoring import telegram_counters
from drivebench.services.monitoring.monitor import SERVICE_GROUPS, monitor_for
from drivebench.services.monitoring.recording import format_names, recordings_for
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep, StateDep
from drivebench.web.root import under_root
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
BUS_LABELS = {"active": N_("active"), "warning": N_("warning"), "passive": N_("error passive"),
              "bus-off": N_("bus-off")}  # translated where shown (monitor.html)


def _recordings(session: Session, **extra: Any) -> dict[str, Any]:
    recordings = recordings_for(session)
    return {"session_id": session.id, "formats": format_names(), "recordings": recordings.list(),
            "active": recordings.active, **extra}


def _counter_nodes(session: Session) -> list[dict[str, Any]]:
    return [{"node_id": node_id, "device": node.device_name}
            for node_id, node in sorted(session.nodes.items())
            if telegram_counters.counter_items(session, node_id)]


@router.get("/monitor", response_class=HTMLResponse)
async def monitor_index(request: Request, state: StateDep) -> Response:
    sessions = state.manager.list()
    if sessions:
        return RedirectResponse(under_root(request.scope, f"/monitor/{sessions[0].id}"), status_code=307)
    return templates.TemplateResponse(request, "monitor.html", {"active": "monitor", "session": None,
                                                                "sessions": []})


@router.get("/monitor/{session_id}", response_class=HTMLResponse)
async def monitor_page(request: Request, state: StateDep, session: SessionDep) -> Response:
    monitor = monitor_for(session)
    snapshot = monitor.snapshot()
    bus_text = " ".join(filter(None, [snapshot["bus_text"], (snapshot["flood"] or {}).get("text")]))
    context = {"active": "monitor", "session": session_public(session),
               "sessions": [session_public(s) for s in state.manager.list()],
               "service_groups": SERVICE_GROUPS, "filter": monitor.filter.as_dict(), "paused": monitor.paused,
               "bus": snapshot["bus"], "bus_text": bus_text, "bus_labels": BUS_LABELS,
               "nodes": sorted(session.nodes), "counter_nodes": _counter_nodes(session),
               "mailbox": _mailbox(session), **_recordings(session)}
    return templates.TemplateResponse(request, "monitor.html", context)


def _mailbox(session: Session) -> list[NodePublic] | None:
    """EtherCAT: the slaves with their mailbox counters; None on CAN."""
    if not session.network.capabilities.mailbox_counters:
        return None
    return [node for node in nodes_public(session) if node.mailbox is not None]


@router.get("/ui/monitor/{session_id}/mailbox", response_class=HTMLResponse)
async def mailbox_block(request: Request, session: SessionDep) -> Response:
    return templates.TemplateResponse(request, "monitor.html", {"session": session_public(session),
                                                                "mailbox": _mailbox(session) or []},
                                      block_name="mailbox")


@router.get("/ui/monitor/{session_id}/recordings", response_class=HTMLResponse)
async def recordings_block(request: Request, session: SessionDep) -> Response:
    return templates.TemplateResponse(request, "monitor.html", _recordings(session), block_name="recordings")


@router.post("/ui/monitor/{session_id}/recordings", response_class=HTMLResponse)
async def start_recording(request: Request, session: SessionDep, format: Annotated[str, Form()] = "pcapng"
                          ) -> Response:
    recordings_for(session).start(format)
    return templates.TemplateResponse(request, "monitor.html", _recordings(session), block_name="recordings")


@router.post("/ui/monitor/{session_id}/recordings/stop", response_class=HTMLResponse)
async def stop_recording(request: Request, session: SessionDep) -> Response:
    recorder = recordings_for(session).stop()
    done = ngettext("Recorded {count} telegram to {file}", "Recorded {count} telegrams to {file}",
                    recorder.frames).format(count=recorder.frames, file=recorder.path.name)
    return templates.TemplateResponse(request, "monitor.html", _recordings(session, done=done),
                                      block_name="recordings")


@router.get("/ui/monitor/{session_id}/device-counters", response_class=HTMLResponse)
async def device_counters(request: Request, session: SessionDep,
                          node_id: Annotated[int, Query(ge=1, le=127)]) -> Response:
    comparison = await telegram_counters.compare(session, monitor_for(session), node_id)
    return templates.TemplateResponse(request, "monitor.html", {"comparison": comparison},
                                      block_name="device_counters")
