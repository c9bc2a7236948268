"""The "New line" wizard page of a session and a run (from the Line project page: "Commission this line"): seven
steps, each with its action and its result in words; the page script (line_wizard.js) calls
``/api/sessions/{session}/line-wizard`` and asks the confirmation dialog where a step answers 428 (app.js). The run
lives in the database: a reload (or a restarted server) shows where it stood. The report is a page of its own."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.services.bus.sessions import Session
from drivebench.services.line.project import LineProject
from drivebench.services.line.store import LineProjectStore
from drivebench.services.line.wizard_report import report
from drivebench.services.line.wizard_run import STATE_WORDS, STEP_TITLES, STEPS, WizardRun, WizardStore
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import RowId, SessionDep
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


async def _run_and_project(session: Session, run_id: int) -> tuple[WizardRun, LineProject | None]:
    run = await asyncio.to_thread(WizardStore().get, run_id, session.id)
    if run.project_id is None:
        return run, None
    return run, (await asyncio.to_thread(LineProjectStore().get, run.project_id)).project


@router.get("/sessions/{session_id}/line-wizard/{run_id}", response_class=HTMLResponse)
async def wizard_page(request: Request, session: SessionDep, run_id: RowId) -> Response:
    run, project = await _run_and_project(session, run_id)
    return templates.TemplateResponse(request, "line_wizard.html", {
        "active": "line", "session": session, "run": run, "project": project,
        "steps": [(number, name, STEP_TITLES[name]) for number, name in enumerate(STEPS, start=1)]})


@router.get("/sessions/{session_id}/line-wizard/{run_id}/report", response_class=HTMLResponse)
async def report_page(request: Request, session: SessionDep, run_id: RowId) -> Response:
    run, project = await _run_and_project(session, run_id)
    return templates.TemplateResponse(request, "line_wizard_report.html", {
        "active": "line", "session": session, "report": report(run, project), "state_words": STATE_WORDS})
