"""The "New line" wizard of a session (issue 32 step 4): a run per line project, kept in the database.

* ``POST /api/sessions/{s}/line-wizard`` ``{"project_id": …}``: a new run (201).
* ``GET  …/line-wizard``: the session's runs, newest first; ``GET …/line-wizard/{run}``: one run.
* ``PUT  …/line-wizard/{run}/assignments`` ``{"20": "0x000003E9", …}``: which found device (serial) takes which
  planned node.
* ``POST …/line-wizard/{run}/firmware/{node}`` (multipart ``file``, optional ``identity``): a firmware file checked
  for the node (program download's check), used by the program step.
* ``POST …/line-wizard/{run}/steps/{step}`` (scan, assign, store, boot_check, sets, program) with ``confirm`` and
  ``confirm_values`` where the step asks (428): runs one step (again) and answers the run.
* ``GET  …/line-wizard/{run}/report``: the report (``?download=1``: as a file).
"""

from __future__ import annotations

import asyncio
import json
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Request, Response, UploadFile, status
from pydantic import BaseModel, Field

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.line.project import LineProject
from drivebench.services.line.store import LineProjectStore
from drivebench.services.line.wizard_report import WizardReport, report
from drivebench.services.line.wizard_run import Firmware, WizardRun, WizardStore, refuse_while_running
from drivebench.services.line.wizard_steps import StepCall, run_step
from drivebench.services.program import download
from drivebench.services.program.firmware import read_firmware
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import MAX_ROW_ID, JobsDep, RowId, SessionDep
from drivebench.web.safety import AuditUserDep, WriteCtxDep, confirmation

router = APIRouter(route_class=DeferredRoute, prefix="/api/sessions/{session_id}/line-wizard", tags=["line wizard"],
                   responses={428: {"description": "Not confirmed with the node (or all) and the values"}})


class RunIn(BaseModel):
    project_id: int = Field(ge=1, le=MAX_ROW_ID)


class StepIn(BaseModel):
    confirm: int | str | None = Field(None, description="'all' (or the header X-DriveBench-Confirm)")
    confirm_values: dict[str, Any] | None = Field(None, description="the values the 428 named, repeated")
    window_ms: float = Field(50, description="the scan's answer window (LSS fastscan)")


def _project(run: WizardRun) -> LineProject:
    if run.project_id is None:
        raise InvalidValue(_("The line project of this run was deleted: start a new run from a project."))
    return LineProjectStore().get(run.project_id).project


@router.post("", response_model=WizardRun, status_code=status.HTTP_201_CREATED)
async def start_run(body: RunIn, session: SessionDep, user: AuditUserDep) -> WizardRun:
    if session.ethercat is not None:
        raise InvalidValue(_("The New line wizard addresses CANopen devices by LSS; session '{session}' is an "
                             "EtherCAT segment.").format(session=session.name))
    project = await asyncio.to_thread(LineProjectStore().get, body.project_id)
    run = WizardRun(session_id=session.id, project_id=project.id, project_name=project.name, created_by=user)
    return await asyncio.to_thread(WizardStore().create, run)


@router.get("", response_model=list[WizardRun])
async def list_runs(session: SessionDep) -> list[WizardRun]:
    return await asyncio.to_thread(WizardStore().list, session.id)


@router.get("/{run_id}", response_model=WizardRun)
async def get_run(run_id: RowId, session: SessionDep) -> WizardRun:
    return await asyncio.to_thread(WizardStore().get, run_id, session.id)


@router.put("/{run_id}/assignments", response_model=WizardRun)
async def set_assignments(run_id: RowId, body: dict[int, str | None], session: SessionDep) -> WizardRun:
    """Planned node ID -> serial of a found device (``null`` or missing: none). Every serial once, every node in
    the project, every serial found by the scan."""
    store = WizardStore()
    run = await asyncio.to_thread(store.get, run_id, session.id)
    refuse_while_running(run)
    planned = {node.node_id for node in _project(run).nodes}
    found = {int(device.serial, 16): device.serial for device in run.found}
    chosen: dict[int, str] = {}
    for node_id, serial in body.items():
        if serial is None or serial == "":
            continue
        if node_id not in planned:
            raise InvalidValue(_("Node {node} is not a planned node of the project.").format(node=node_id))
        try:
            number = int(serial, 16) if serial.lower().startswith("0x") else int(serial)
        except ValueError as exc:
            raise InvalidValue(_("'{text}' is not a number (decimal or 0x hex)").format(text=serial)) from exc
        if number not in found:
            raise InvalidValue(_("No device with serial {serial} was found by the scan.").format(serial=serial))
        if found[number] in chosen.values():
            raise InvalidValue(_("Serial {serial} is given to two nodes: a device takes one node ID.").format(
                serial=found[number]))
        chosen[node_id] = found[number]
    run.assignments = chosen
    return await asyncio.to_thread(store.save, run)


@router.post("/{run_id}/firmware/{node_id}", response_model=WizardRun)
async def choose_firmware(run_id: RowId, node_id: Annotated[int, Field(ge=1, le=127)], session: SessionDep,
                          file: Annotated[UploadFile, File()],
                          identity: Annotated[str | None, Form()] = None) -> WizardRun:
    """The node's firmware file, checked as the program download checks it (nothing is sent)."""
    store = WizardStore()
    run = await asyncio.to_thread(store.get, run_id, session.id)
    _project(run).node(node_id)
    session.node(node_id)
    firmware = read_firmware(file.filename or "firmware.bin", await file.read(), identity)
    checked = await download.check(session, node_id, firmware)
    if not checked["ok"]:
        raise InvalidValue(str(checked["refused"]))
    run = await asyncio.to_thread(store.get, run_id, session.id)
    refuse_while_running(run)
    run.firmware[node_id] = Firmware(file_id=str(checked["file_id"]), name=firmware.name, size=len(firmware.image),
                                     crc32=f"0x{firmware.crc32:08X}")
    return await asyncio.to_thread(store.save, run)


@router.post("/{run_id}/steps/{step}", response_model=WizardRun)
async def run_one_step(request: Request, run_id: RowId, step: str, session: SessionDep, jobs: JobsDep,
                       ctx: WriteCtxDep, body: StepIn | None = None) -> WizardRun:
    """One step, run (again): its result in words in the run. A step that reaches every device asks first (428,
    ``confirm_node`` all); refused while a node is enabled or armed (409)."""
    body = body or StepIn()
    store = WizardStore()
    run = await asyncio.to_thread(store.get, run_id, session.id)
    project = await asyncio.to_thread(_project, run)
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    call = StepCall(run=run, session=session, project=project, ctx=ctx, jobs=jobs, window_ms=body.window_ms)
    return await run_step(call, step, store)


@router.get("/{run_id}/report", response_model=WizardReport)
async def get_report(run_id: RowId, session: SessionDep, download: bool = False) -> Response:
    run = await asyncio.to_thread(WizardStore().get, run_id, session.id)
    project = None
    if run.project_id is not None:
        project = (await asyncio.to_thread(LineProjectStore().get, run.project_id)).project
    body = report(run, project).model_dump(mode="json")
    headers = {"Content-Disposition": f'attachment; filename="new-line-report-{run.id}.json"'} if download else {}
    return Response(json.dumps(body, indent=2, ensure_ascii=False), media_type="application/json", headers=headers)
