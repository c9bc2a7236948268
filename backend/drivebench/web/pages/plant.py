"""The Plant screen: sessions, their nodes with live NMT state, NMT buttons, scan, add node.

NMT start needs the confirmation field naming the node (``all`` for the broadcast) and is kept alive by the page's
keep-alive socket (``/ws/sessions/{session}/keepalive``, safety.js): closing the page stops what it started.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.errors import Conflict, DriveBenchError
from drivebench.i18n import N_, _
from drivebench.protocol.canopen.nmt import COMMAND_BY_NAME
from drivebench.services.bus.fieldbus import ETHERCAT_INTERFACES, SessionSpec, interface_notes, parse_spec
from drivebench.services.bus.sessions import Session
from drivebench.services.bus.views import nodes_public, session_public
from drivebench.services.control.drive_guard import parse_values
from drivebench.services.profiles import loading as profiles_loading
from drivebench.transport.bus import BusSpec, known_interfaces
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import ManagerDep, SessionDep, StateDep
from drivebench.web.nmt import NodeNmtRequest, send_nmt
from drivebench.web.problems import error_fragment, problem_body
from drivebench.web.safety import PanelDep, WriteCtxDep
from drivebench.web.state import app_state
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


def _context(state: Any, **extra: Any) -> dict[str, Any]:
    sessions = [{"session": session_public(s), "nodes": nodes_public(s)} for s in state.manager.list()]
    return {"active": "plant", "sessions": sessions, "interfaces": [*known_interfaces(), *ETHERCAT_INTERFACES],
            "interface_notes": interface_notes(),
            "profiles": state.registry.all(),
            "form": {"interface": "socketcand", "channel": "", "bitrate": 500000, "name": ""}, **extra}


def nodes_table(request: Request, session: Session) -> Response:
    return templates.TemplateResponse(request, "plant.html", {"session_id": session.id,
                                                              "nodes": nodes_public(session)},
                                      block_name="nodes_table")


@router.get("/", response_class=HTMLResponse)
async def plant_page(request: Request, state: StateDep) -> Response:
    return templates.TemplateResponse(request, "plant.html", _context(state))


@router.post("/ui/sessions", response_class=HTMLResponse)
async def open_session(request: Request, state: StateDep, manager: ManagerDep,
                       interface: Annotated[str, Form()], channel: Annotated[str, Form()] = "",
                       bitrate: Annotated[int, Form()] = 500000, name: Annotated[str, Form()] = ""
                       ) -> Response:
    form = {"interface": interface, "channel": channel, "bitrate": bitrate, "name": name}
    try:
        if interface == "socketcand":
            spec: SessionSpec = BusSpec.parse(f"socketcand:{channel}@{bitrate}")
        elif interface in ETHERCAT_INTERFACES:
            spec = parse_spec(f"{interface}:{channel}")
        else:
            spec = BusSpec.build(interface=interface, channel=channel, bitrate=bitrate)
        session = await manager.open(spec, name or None)
    except DriveBenchError as exc:
        body = problem_body(exc, str(request.url.path))
        return templates.TemplateResponse(request, "plant.html", _context(state, form=form,
                                          form_error=error_fragment(body)),
                                          block_name="open_form", status_code=int(body["status"]))  # type: ignore[call-overload]
    response = templates.TemplateResponse(request, "plant.html",
                                          _context(state, form=form, form_ok=f"Opened {session.spec}"),
                                          block_name="open_form")
    response.headers["HX-Refresh"] = "true"
    return response


@router.post("/ui/sessions/{session_id}/close", response_class=HTMLResponse)
async def close_session(session: SessionDep, manager: ManagerDep) -> Response:
    await manager.close(session.id)
    return HTMLResponse("")


@router.post("/ui/sessions/{session_id}/nmt", response_class=HTMLResponse)
async def nmt(request: Request, session: SessionDep, panel: PanelDep, ctx: WriteCtxDep, command: Annotated[str, Form()],
              node_id: Annotated[int, Form(ge=0, le=127)] = 0, confirm: Annotated[str, Form()] = "",
              confirm_values: Annotated[str, Form()] = "") -> Response:
    if command not in COMMAND_BY_NAME:
        raise DriveBenchError(_("Unknown NMT command '{command}'").format(command=command))
    if node_id:
        session.node(node_id)
    await send_nmt(request, session, NodeNmtRequest(
        command=command, confirm=confirm or None, confirm_values=parse_values(confirm_values)),
                   node_id, panel, ctx)
    return nodes_table(request, session)


@router.post("/ui/sessions/{session_id}/scan", response_class=HTMLResponse)
async def scan(request: Request, session: SessionDep) -> Response:
    await session.scan()
    return nodes_table(request, session)


@router.post("/ui/sessions/{session_id}/nodes", response_class=HTMLResponse)
async def add_node(request: Request, session: SessionDep, node_id: Annotated[int, Form(ge=1, le=127)],
                   profile_id: Annotated[str, Form()] = "") -> Response:
    known = session.nodes.get(node_id)
    if known is not None:  # adding it again would silently replace its profile (and its name)
        raise Conflict(_("Node {node} is already in session '{session}' as {device}.").format(
            node=node_id, session=session.name, device=known.device_name),
                       hint=N_("Scan the bus to read its identity again."))
    await profiles_loading.profiles_known(app_state(request.app).registry, [profile_id])
    session.add_node(node_id, profile_id or None)
    return nodes_table(request, session)
