"""The Scope screen: channels from the session's nodes, trigger, the live plot of a recording, stored recordings.
Through a share link that shows the scope it is read-only: the live plot and the stored recordings. The page's
script (static/scope.js) speaks the JSON API (web/api/scope.py) and the scope websocket."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from drivebench.services.bus.views import session_public
from drivebench.services.scope.channels import MAX_CHANNELS
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep, StateDep
from drivebench.web.root import under_root
from drivebench.web.templating import templates
from drivebench.web.viewer import viewer_of

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


@router.get("/scope", response_class=HTMLResponse)
async def scope_index(request: Request, state: StateDep) -> Response:
    sessions = state.manager.list()
    if sessions:
        return RedirectResponse(under_root(request.scope, f"/scope/{sessions[0].id}"), status_code=307)
    return templates.TemplateResponse(request, "scope.html", {"active": "scope", "session": None, "sessions": []})


@router.get("/scope/{session_id}", response_class=HTMLResponse)
async def scope_page(request: Request, state: StateDep, session: SessionDep) -> Response:
    nodes = [{"node_id": node.node_id, "device": node.name or node.device_name}
             for node in sorted(session.nodes.values(), key=lambda n: n.node_id)]
    context = {"active": "scope", "session": session_public(session),
               "sessions": [session_public(s) for s in state.manager.list()], "nodes": nodes,
               "max_channels": MAX_CHANNELS, "node": int(request.query_params.get("node") or 0) or None}
    if (link := viewer_of(request)) is not None:  # a share link: watch and open, no picker, no Start/Stop/Delete
        context.update(viewer=link, sessions=[session_public(session)])
    return templates.TemplateResponse(request, "scope.html", context)
