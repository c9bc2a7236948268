"""Program download (CiA 302-3) of one node: check a firmware file, download it as a job, program control, and the
node's program identification.

* ``GET  .../program``: 0x1F51 state, 0x1F56 software identification, 0x1F57 flash status in words (and the next
  step where the device waits in its bootloader).
* ``POST .../program/check`` (multipart: ``file``, optional ``identity``: the file's identification as JSON): the file
  checked (Intel HEX records and checksums) against the node's 0x1018; a ``file_id`` for the download when it passes.
* ``POST .../program/download`` ``{"file_id": ...}`` with the confirmation naming the node (428 without it): 202 and the
  job; progress (bytes, rate, ETA) on ``/ws/jobs/{id}``, cancel with ``DELETE /api/jobs/{id}``, the result on
  ``GET .../program/jobs/{id}``.
* ``POST .../program/control/{command}`` (stop, start, reset, clear): 0x1F51, confirmed like any moving write.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Request, UploadFile, status
from pydantic import BaseModel, Field

from drivebench.errors import NotFound
from drivebench.i18n import _, shown
from drivebench.protocol.canopen.program_objects import ProgramCommand
from drivebench.services.params.jobs import Job
from drivebench.services.program import download
from drivebench.services.program.firmware import read_firmware
from drivebench.services.program.program_info import program_info
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import JobsDep, RootDep, SessionDep
from drivebench.web.job_views import JobOut, job_out
from drivebench.web.safety import WriteCtxDep, confirmation

router = APIRouter(prefix="/api/sessions/{session_id}/nodes/{node_id}/program", tags=["program download"],
                   responses={428: {"description": "Not confirmed with the node id and the values"}},
                   route_class=DeferredRoute)
COMMANDS = {"stop": ProgramCommand.STOP, "start": ProgramCommand.START, "reset": ProgramCommand.RESET,
            "clear": ProgramCommand.CLEAR}


class Confirmed(BaseModel):
    confirm: int | str | None = Field(None, description="The node id (or the header X-DriveBench-Confirm)")
    confirm_values: dict[str, Any] | None = Field(None, description="The values the 428 named, repeated (or the "
                                                                    "header X-DriveBench-Confirm-Values)")


class DownloadIn(Confirmed):
    file_id: str = Field(min_length=1, max_length=40, description="From POST .../program/check")


def _plain(value: object) -> object:
    if isinstance(value, str):
        return shown(value)
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_plain(item) for item in value]
    return value


def program_job_out(job: Job, root: str) -> JobOut:
    out = job_out(job, with_result=False, root=root)
    out.result = _plain(job.result)  # type: ignore[assignment]
    return out


@router.get("")
async def get_program(session: SessionDep, node_id: int) -> dict[str, object]:
    return _plain(asdict(await program_info(session, node_id)))  # type: ignore[return-value]


@router.post("/check")
async def check_file(session: SessionDep, node_id: int, file: Annotated[UploadFile, File()],
                     identity: Annotated[str | None, Form()] = None) -> dict[str, object]:
    """The file checked; nothing is sent to the node."""
    session.node(node_id)
    firmware = read_firmware(file.filename or "firmware.bin", await file.read(), identity)
    return _plain(await download.check(session, node_id, firmware))  # type: ignore[return-value]


@router.post("/download", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED)
async def start_download(request: Request, session: SessionDep, node_id: int, body: DownloadIn, jobs: JobsDep,
                         ctx: WriteCtxDep, root: RootDep) -> JobOut:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    firmware = await download.checked_file(session, node_id, body.file_id)
    job = download.start_download(session, node_id, jobs, firmware, ctx)
    return program_job_out(job, root)


@router.get("/jobs/{job_id}", response_model=JobOut)
async def get_job(session: SessionDep, node_id: int, job_id: str, jobs: JobsDep, root: RootDep) -> JobOut:
    job = jobs.get(job_id)
    if job.kind != "program-download" or job.result.get("node_id") not in (None, node_id):
        raise NotFound(_("No program download '{job}' for node {node}").format(job=job_id, node=node_id))
    return program_job_out(job, root)


@router.post("/control/{command}")
async def control(request: Request, session: SessionDep, node_id: int, command: str, ctx: WriteCtxDep,
                  body: Confirmed | None = None) -> dict[str, object]:
    which = COMMANDS.get(command)
    if which is None:
        raise NotFound(_("No program command '{command}' (stop, start, reset, clear)").format(command=command))
    ctx = ctx.confirming(confirmation(request, body and body.confirm, body and body.confirm_values))
    return _plain(await download.control(session, node_id, which, ctx))  # type: ignore[return-value]
