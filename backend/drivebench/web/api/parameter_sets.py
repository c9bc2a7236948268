"""Parameter sets: stored sets (list, rename, delete, history), upload from a node, import/export (JSON, CSV,
DCF), compare two sources, download to a node (preview, job, report, retry, rollback), copy to another node, and
the audit log of every write.

Long work (upload, download, retry, rollback) is a job: ``202`` with the job, progress on ``/ws/jobs/{id}``, the
report at ``/api/parameter-sets/jobs/{id}`` and, once stored, at ``/api/parameter-downloads/{download_id}``.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Header, Query, Request, UploadFile, status
from fastapi.responses import Response

from drivebench.config import settings
from drivebench.device.profiles.loader import original_file, original_xml
from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.sets import set_formats, set_jobs
from drivebench.services.sets.parameter_sets import (
    Comparison,
    SetInfo,
    SetVersion,
    compare,
    comparison_csv,
    retarget,
)
from drivebench.services.sets.set_jobs import ReportLine
from drivebench.services.users import audit
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import JobsDep, ManagerDep, RootDep, RowId, RowVersion, StateDep
from drivebench.web.safety import AuditUserDep, WriteCtxDep, confirmation
from drivebench.web.set_views import (
    CompareIn,
    CopyIn,
    CopyOut,
    DownloadIn,
    DownloadOut,
    FollowUpIn,
    ImportOut,
    SetDetailOut,
    SetJobOut,
    SetUpdate,
    TargetIn,
    UploadIn,
    build_sources,
    detail_out,
    download_out,
    set_job_out,
    store,
)

# downloads take the node lease (WriteCtxDep)
router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["parameter sets"])
SETS = "/parameter-sets"
UserHeader = Annotated[str | None, Header(alias="X-DriveBench-User", description="Who acts (audit log)")]


def user_of(header: str | None, signed_in: str) -> str:
    """Who acts: the X-DriveBench-User header (without login), else who signed in (or the local user)."""
    return (header or "").strip()[:120] or signed_in


# --- sets --------------------------------------------------------------------------------------------------
@router.get(SETS, response_model=list[SetInfo])
async def list_sets(profile_id: str | None = None) -> list[SetInfo]:
    return store().all(profile_id)


@router.get(SETS + "/schema")
async def set_file_schema() -> dict[str, Any]:
    """The JSON schema of a parameter set file (``drivebench.parameter-set/1``)."""
    return set_formats.ParameterSetFile.model_json_schema(by_alias=True)


@router.post(SETS + "/upload", response_model=SetJobOut, status_code=status.HTTP_202_ACCEPTED)
async def upload_from_node(root: RootDep, body: UploadIn, manager: ManagerDep, jobs: JobsDep, ctx: WriteCtxDep,
                           user: UserHeader = None) -> SetJobOut:
    """Read every settable parameter of the node into a new set (the job's ``set_id``)."""
    job = set_jobs.start_upload(manager.get(body.session_id), body.node_id, jobs, store(), ctx=ctx, name=body.name,
                                note=body.note, user=user_of(user, ctx.user))
    return set_job_out(job, root=root)


@router.post(SETS + "/{set_id}/upload", response_model=SetJobOut, status_code=status.HTTP_202_ACCEPTED)
async def upload_new_version(root: RootDep, set_id: RowId, body: TargetIn, manager: ManagerDep, jobs: JobsDep,
                             ctx: WriteCtxDep, user: UserHeader = None) -> SetJobOut:
    """Read the node again into a new version of the set (same device type; the old versions stay)."""
    job = set_jobs.start_upload(manager.get(body.session_id), body.node_id, jobs, store(), name="", into=set_id,
                                ctx=ctx, user=user_of(user, ctx.user))
    return set_job_out(job, root=root)


@router.post(SETS + "/import", response_model=ImportOut, status_code=status.HTTP_201_CREATED)
async def import_set(state: StateDep, who: AuditUserDep, file: Annotated[UploadFile, File()],
                     format: Annotated[str | None, Form()] = None,
                     profile_id: Annotated[str | None, Form()] = None,
                     name: Annotated[str | None, Form()] = None, user: UserHeader = None) -> ImportOut:
    """A JSON, CSV or DCF file checked against the target profile; every value that does not fit is named with
    its line (422, ``errors``) and nothing is stored."""
    data = await file.read(set_formats.MAX_SET_FILE_BYTES + 1)
    if len(data) > set_formats.MAX_SET_FILE_BYTES:
        raise InvalidValue(_("The file is larger than {size} MB").format(
            size=set_formats.MAX_SET_FILE_BYTES // 1024 // 1024))
    filename = file.filename or "upload"
    imported = set_formats.import_any(data, filename, state.registry.get, fmt=format or None,
                                      profile_id=profile_id or None, name=name or None)
    stored = store().create(imported.name, imported.profile, imported.values, user=user_of(user, who),
                            node_id=imported.node_id, note=imported.note, reason=f"imported from {filename}")
    return ImportOut(set=stored.info, notes=imported.notes)


@router.get(SETS + "/{set_id}", response_model=SetDetailOut)
async def get_set(set_id: RowId, state: StateDep, version: RowVersion = None) -> SetDetailOut:
    stored = store().get(set_id, version)
    return detail_out(stored, state.registry.get(stored.info.profile_id))


@router.patch(SETS + "/{set_id}", response_model=SetInfo)
async def update_set(set_id: RowId, body: SetUpdate, state: StateDep, who: AuditUserDep,
                     user: UserHeader = None) -> SetInfo:
    info = store().rename(set_id, body.name, body.note, base_version=body.version)
    if body.values:
        edited = store().get(set_id, body.version)
        changes = set_formats.checked_values(state.registry.get(info.profile_id), body.values,
                                             _("Parameter set {id}").format(id=set_id))
        info = store().update_values(set_id, {**edited.values, **changes}, user=user_of(user, who), reason=body.reason,
                                     base_version=edited.version).info
    return info


@router.delete(SETS + "/{set_id}", status_code=status.HTTP_204_NO_CONTENT)
async def delete_set(set_id: RowId) -> Response:
    store().delete(set_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get(SETS + "/{set_id}/history", response_model=list[SetVersion])
async def set_history(set_id: RowId) -> list[SetVersion]:
    return store().history(set_id)


@router.get(SETS + "/{set_id}/export")
async def export_set(set_id: RowId, state: StateDep,
                     format: Annotated[Literal["json", "csv", "dcf", "xdc"], Query()] = "json",
                     version: RowVersion = None) -> Response:
    stored = store().get(set_id, version)
    profile = state.registry.get(stored.info.profile_id)
    text, media = set_formats.export(format, stored, profile, original_file(state.registry, profile),
                                     original_xml(state.registry, profile))
    filename = set_formats.file_name(stored, format)
    return Response(text, media_type=media, headers={"Content-Disposition": f'attachment; filename="{filename}"'})


@router.post(SETS + "/{set_id}/copy", response_model=CopyOut, status_code=status.HTTP_201_CREATED)
async def copy_set(set_id: RowId, body: CopyIn, state: StateDep, who: AuditUserDep,
                   user: UserHeader = None) -> CopyOut:
    """A new set for an identical drive at ``to_node``: node address and node-id based COB-IDs moved along."""
    stored = store().get(set_id)
    profile = state.registry.get(stored.info.profile_id)
    from_node = body.from_node or stored.info.node_id
    if from_node is None:
        raise InvalidValue(_("The set was not uploaded from a node: give from_node"))
    values, notes = retarget(profile, stored.values, from_node, body.to_node)
    copy = store().create(body.name or _("{name} (node {node})").format(name=stored.info.name, node=body.to_node),
                          profile, values, user=user_of(user, who), node_id=body.to_node,
                          session_id=stored.info.session_id,
                          note=_("Copy of set {id} v{version} for node {node}").format(
                              id=set_id, version=stored.version, node=body.to_node),
                          reason=f"copy of set {set_id} v{stored.version} for node {body.to_node}")
    return CopyOut(set=copy.info, notes=notes)


# --- compare -----------------------------------------------------------------------------------------------
@router.post(SETS + "/compare", response_model=Comparison)
async def compare_sources(body: CompareIn, state: StateDep, manager: ManagerDep, ctx: WriteCtxDep,
                          format: Annotated[Literal["json", "csv"], Query()] = "json") -> Any:
    """Only the differences, scaled with units, filtered by ``q`` (code or name words) and ``group``;
    ``format=csv`` exports them."""
    left, right = await build_sources(state, manager, body, ctx)
    result = compare(left, right, query=body.q, group=body.group)
    if format == "csv":
        return Response(comparison_csv(result), media_type="text/csv",
                        headers={"Content-Disposition": 'attachment; filename="comparison.csv"'})
    return result


# --- download ----------------------------------------------------------------------------------------------
@router.post(SETS + "/{set_id}/preview", response_model=list[ReportLine])
async def preview_download(set_id: RowId, body: TargetIn, manager: ManagerDep, ctx: WriteCtxDep,
                           version: RowVersion = None) -> list[ReportLine]:
    """What a download would change (device values read now), in the order it would write them."""
    stored = store().get(set_id, version)
    lines = await set_jobs.preview(manager.get(body.session_id), body.node_id, stored, ctx=ctx)
    return lines


@router.post(SETS + "/{set_id}/download", response_model=SetJobOut, status_code=status.HTTP_202_ACCEPTED)
async def download_set(root: RootDep, request: Request, set_id: RowId, body: DownloadIn, manager: ManagerDep,
                       jobs: JobsDep, ctx: WriteCtxDep, version: RowVersion = None,
                       user: UserHeader = None) -> SetJobOut:
    stored = store().get(set_id, version)
    session = manager.get(body.session_id)
    held = await set_jobs.held_moving(session, body.node_id, set_jobs.download_targets(session, body.node_id, stored),
                                      ctx=ctx)
    job = set_jobs.start_download(session, body.node_id, jobs, store(), stored, ctx=ctx, save=body.save,
                                  user=user_of(user, ctx.user), held=held,
                                  confirm=confirmation(request, body.confirm, body.confirm_values))
    return set_job_out(job, root=root)


@router.get(SETS + "/jobs/{job_id}", response_model=SetJobOut)
async def get_set_job(root: RootDep, job_id: str, jobs: JobsDep) -> SetJobOut:
    return set_job_out(jobs.get(job_id), root=root)


@router.get("/parameter-downloads", response_model=list[DownloadOut])
async def list_downloads(jobs: JobsDep, node_id: Annotated[int | None, Query(ge=1, le=127)] = None,
                         limit: Annotated[int, Query(ge=1, le=500)] = 50) -> list[DownloadOut]:
    return [download_out(row, jobs) for row in store().downloads(node_id=node_id, limit=limit)]


@router.get("/parameter-downloads/{download_id}", response_model=DownloadOut)
async def get_download(download_id: RowId, jobs: JobsDep) -> DownloadOut:
    return download_out(store().download(download_id), jobs)


@router.post("/parameter-downloads/{download_id}/retry", response_model=SetJobOut,
             status_code=status.HTTP_202_ACCEPTED)
async def retry_download(root: RootDep, request: Request, download_id: RowId, manager: ManagerDep, jobs: JobsDep,
                         ctx: WriteCtxDep, body: FollowUpIn | None = None, user: UserHeader = None) -> SetJobOut:
    """Write again what the download left failed, mismatched or not attempted."""
    row = store().download(download_id)
    session = manager.get(row.session_id)
    held = await set_jobs.held_moving(session, row.node_id, set_jobs.retry_targets(store(), download_id), ctx=ctx)
    job = set_jobs.start_retry(session, jobs, store(), download_id, ctx=ctx, held=held,
                               save=bool(body and body.save), user=user_of(user, ctx.user),
                               confirm=confirmation(request, body and body.confirm, body and body.confirm_values))
    return set_job_out(job, root=root)


@router.post("/parameter-downloads/{download_id}/rollback", response_model=SetJobOut,
             status_code=status.HTTP_202_ACCEPTED)
async def rollback_download(root: RootDep, request: Request, download_id: RowId, manager: ManagerDep, jobs: JobsDep,
                            ctx: WriteCtxDep, body: FollowUpIn | None = None, user: UserHeader = None) -> SetJobOut:
    """Write back the values read before the download, for everything it changed (or may have changed)."""
    row = store().download(download_id)
    session = manager.get(row.session_id)
    held = await set_jobs.held_moving(session, row.node_id, set_jobs.rollback_targets(store(), download_id),
                                      ctx=ctx)
    job = set_jobs.start_rollback(session, jobs, store(), download_id, ctx=ctx, held=held,
                                  save=bool(body and body.save), user=user_of(user, ctx.user),
                                  confirm=confirmation(request, body and body.confirm, body and body.confirm_values))
    return set_job_out(job, root=root)


# --- audit log ---------------------------------------------------------------------------------------------
@router.get("/audit", response_model=list[audit.AuditEntry])
async def audit_log(request: Request, node_id: Annotated[int | None, Query(ge=0, le=127)] = None,
                    session_id: str | None = None, q: str = "",
                    origin: str | None = None, limit: Annotated[int, Query(ge=1, le=100_000)] = 1000,
                    format: Annotated[Literal["json", "csv"], Query()] = "json") -> Any:
    """Every write the tool sent, newest first; ``format=csv`` exports it."""
    found = audit.entries(settings.database_url, node_id=node_id, session_id=session_id, query=q, origin=origin,
                          limit=limit)
    if format == "csv":
        return Response(audit.to_csv(found), media_type="text/csv",
                        headers={"Content-Disposition": 'attachment; filename="audit-log.csv"'})
    return found
