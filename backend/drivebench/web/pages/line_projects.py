"""The Line project page (issue 32): open a project file, export it, run the boot-up check of a session against it,
preview and download a node's concise DCF. The page's script talks to ``/api/line-projects``."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.services.line.store import LineProjectStore
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import ManagerDep
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


@router.get("/line-projects", response_class=HTMLResponse)
async def line_projects_page(request: Request, manager: ManagerDep) -> Response:
    projects = await asyncio.to_thread(LineProjectStore().list)
    sessions = [session for session in manager.list() if session.ethercat is None]
    return templates.TemplateResponse(request, "line_projects.html",
                                      {"active": "line", "projects": projects, "sessions": sessions})
