"""What the parameter sets' API and page share: the set store, request and answer models, conversions, the
sources of a comparison."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, Field

from drivebench.device.profiles.profile import Profile
from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.params.jobs import Job, JobManager
from drivebench.services.params.write_context import WriteContext
from drivebench.services.session_manager import SessionManager
from drivebench.services.sets import set_jobs
from drivebench.services.sets.download_outcome import DownloadOutcome, outcome_of
from drivebench.services.sets.parameter_sets import (
    ParameterSetStore,
    SetInfo,
    Source,
    StoredSet,
    catalog_for,
    defaults_source,
    set_source,
    shown,
)
from drivebench.services.sets.set_jobs import ReportLine
from drivebench.services.storage.models import DownloadRow
from drivebench.web.deps import MAX_ROW_ID
from drivebench.web.job_views import JobOut, job_out
from drivebench.web.state import AppState


def store() -> ParameterSetStore:
    return ParameterSetStore()  # settings.database_url, read at each call


# --- models (sets, versions, comparisons and report lines are the services' own) ---------------------------
class SetValueOut(BaseModel):
    ref: str
    name: str
    raw: int | float | str
    display: str | None
    unit: str | None


class SetDetailOut(SetInfo):
    shown_version: int
    values: list[SetValueOut]


class SetUpdate(BaseModel):
    """An edit of a set. ``version`` is the version the client edited: if the set has a newer one (another user, on
    this server or another of the database), the edit is refused with 409 naming who changed it and when."""

    name: str | None = Field(None, min_length=1, max_length=200)
    note: str | None = Field(None, max_length=4000)
    version: int | None = Field(None, ge=1, le=MAX_ROW_ID)
    values: dict[str, float | int | str] | None = Field(
        None, max_length=20_000, description="Changed values by ref (engineering values): a new version")
    reason: str = Field("edited", min_length=1, max_length=300)


class UploadIn(BaseModel):
    session_id: str
    node_id: int = Field(ge=1, le=127)
    name: str = Field(min_length=1, max_length=200)
    note: str = ""


class SourceIn(BaseModel):
    """One side of a comparison: a stored set (version: newest when omitted), a node's values read now, or a
    profile's defaults."""

    kind: Literal["set", "node", "defaults"]
    set_id: int | None = Field(None, ge=1, le=MAX_ROW_ID)
    version: int | None = Field(None, ge=1, le=MAX_ROW_ID)
    session_id: str | None = None
    node_id: int | None = Field(None, ge=1, le=127)
    profile_id: str | None = None


class CompareIn(BaseModel):
    left: SourceIn
    right: SourceIn
    q: str = ""
    group: str | None = None


class TargetIn(BaseModel):
    session_id: str
    node_id: int = Field(ge=1, le=127)


CONFIRM = Field(None, description="The node id, when the set writes values that can make the drive move (control "
                                 "word, setpoint, mode, command source); or X-DriveBench-Confirm")
CONFIRM_VALUES = Field(None, description="With confirm: the values the 428 named (confirm_values), repeated; or "
                                         "X-DriveBench-Confirm-Values")


class DownloadIn(TargetIn):
    save: bool = Field(False, description="Save on the device at the end (C00002/11, 0x1010 ...) if all went in")
    confirm: int | str | None = CONFIRM
    confirm_values: dict[str, Any] | None = CONFIRM_VALUES


class FollowUpIn(BaseModel):
    save: bool = False
    confirm: int | str | None = CONFIRM
    confirm_values: dict[str, Any] | None = CONFIRM_VALUES


class CopyIn(BaseModel):
    to_node: int = Field(ge=1, le=127)
    name: str | None = Field(None, min_length=1, max_length=200)
    from_node: int | None = Field(None, ge=1, le=127, description="Default: the node the set was uploaded from")


class CopyOut(BaseModel):
    set: SetInfo
    notes: list[str]


class DownloadOut(BaseModel):
    id: int
    kind: str
    set_id: int | None
    set_version: int | None
    session_id: str
    node_id: int
    profile_id: str
    user: str
    started: datetime
    finished: datetime | None
    state: str
    """``running``, ``done``, ``incomplete`` (some failed), ``cancelled``, ``failed`` or ``interrupted`` (the
    server stopped during it: the values read first are stored, roll back to restore them)."""
    counts: dict[str, int]
    """Report lines by status."""
    outcome: DownloadOutcome
    """Written, verified, failed, not written: what ``state`` is judged by."""
    report: list[ReportLine]


class SetJobOut(JobOut):
    set_id: int | None = None
    version: int | None = None
    download_id: int | None = None
    download_state: str | None = None
    outcome: DownloadOutcome | None = None
    """A download, retry or rollback: written, verified, failed, not written so far (its end ``state`` is judged
    by them: ``done``, ``incomplete``, or ``failed`` when nothing was written)."""
    report: list[ReportLine] = []


class ImportOut(BaseModel):
    set: SetInfo
    notes: list[str]


# --- conversions -------------------------------------------------------------------------------------------
def detail_out(stored: StoredSet, profile: Profile) -> SetDetailOut:
    catalog = catalog_for(profile)
    values = []
    for ref, raw in stored.values.items():
        item = set_jobs._resolve(catalog, ref)
        values.append(SetValueOut(ref=ref, name=item.name if item else _("(not in the profile)"), raw=raw,
                                  display=shown(item, raw) if item else str(raw),
                                  unit=item.entry.unit if item else None))
    return SetDetailOut(**stored.info.model_dump(), shown_version=stored.version, values=values)


def download_out(row: DownloadRow, jobs: JobManager) -> DownloadOut:
    counts: dict[str, int] = {}
    for line in row.report:
        counts[line["status"]] = counts.get(line["status"], 0) + 1
    return DownloadOut(id=row.id, kind=row.kind, set_id=row.set_id, set_version=row.set_version,
                       session_id=row.session_id, node_id=row.node_id, profile_id=row.profile_id, user=row.user,
                       started=row.started, finished=row.finished, state=set_jobs.download_state(row, jobs),
                       counts=counts, outcome=outcome_of(row.report),
                       report=[set_jobs.report_line(line) for line in row.report])


def set_job_out(job: Job, root: str = "") -> SetJobOut:
    base = job_out(job, with_result=False, root=root)
    report = job.result.get("report", [])
    return SetJobOut(**base.model_dump(), set_id=job.result.get("set_id"), version=job.result.get("version"),
                     download_id=job.result.get("download_id"), download_state=job.result.get("state"),
                     outcome=None if job.kind == "upload" else outcome_of(report),
                     report=[set_jobs.report_line(line) for line in report])


def resolve_source(state: AppState, manager: SessionManager, spec: SourceIn) -> Source | tuple[str, int, list[str]]:
    """A set or defaults source now; a node source as (session, node, refs) to read (async, see compare route)."""
    if spec.kind == "set":
        if spec.set_id is None:
            raise InvalidValue(_("A set source needs set_id"))
        stored = store().get(spec.set_id, spec.version)
        return set_source(stored, state.registry.get(stored.info.profile_id))
    if spec.kind == "defaults":
        if spec.profile_id is None:
            raise InvalidValue(_("A defaults source needs profile_id"))
        return defaults_source(state.registry.get(spec.profile_id), spec.node_id)
    if spec.session_id is None or spec.node_id is None:
        raise InvalidValue(_("A node source needs session_id and node_id"))
    manager.get(spec.session_id).node(spec.node_id)
    return (spec.session_id, spec.node_id, [])


async def build_sources(state: AppState, manager: SessionManager, body: CompareIn, ctx: WriteContext
                        ) -> tuple[Source, Source]:
    sides = [resolve_source(state, manager, body.left), resolve_source(state, manager, body.right)]
    done: list[Source] = []
    for side in sides:
        if isinstance(side, Source):
            done.append(side)
        else:
            done.append(await set_jobs.device_source(manager.get(side[0]), side[1], ctx=ctx))
    return done[0], done[1]
