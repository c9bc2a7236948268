"""The Parameter sets screen (htmx blocks of sets.html): stored sets, upload from a node, import, set detail
(rename, history, export, copy, delete), compare, download (preview -> progress -> report -> retry / roll back)
and the audit log. The work is done by the services; these routes parse forms and pick a block."""

from __future__ import annotations

import re
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response
from markupsafe import escape
from starlette.datastructures import FormData, UploadFile

from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.params.jobs import Job, JobManager
from drivebench.services.params.write_context import WriteContext
from drivebench.services.session_manager import SessionManager
from drivebench.services.sets import set_formats, set_jobs
from drivebench.services.sets.parameter_sets import compare, comparison_csv, retarget
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import JobsDep, ManagerDep, RowId, StateDep
from drivebench.web.pages.sets_audit import audit_context
from drivebench.web.problems import error_fragment, problem_body, status_for
from drivebench.web.safety import WriteCtxDep, audit_user, confirmation
from drivebench.web.set_views import (
    CompareIn,
    SourceIn,
    build_sources,
    detail_out,
    download_out,
    set_job_out,
    store,
)
from drivebench.web.state import AppState
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)  # downloads take the node lease (WriteCtxDep)
_DEVICE_NOISE = re.compile(r"^Inverter Drives\s+|\s+(frequency inverter|servo inverter)?\s*with .*$| - .*$")


def short_device(product_name: str) -> str:
    """``Inverter Drives 8400 motec - CANopen communication unit E84DGFCxxx`` -> ``8400 motec``."""
    return _DEVICE_NOISE.sub("", product_name).strip() or product_name


templates.env.filters["short_device"] = short_device
PAGE = "sets.html"
UI = "/parameter-sets"
CHANGED_EVENT = {"HX-Trigger": "sets-changed"}


def _render(request: Request, block: str | None, context: dict[str, Any], status: int = 200,
            headers: dict[str, str] | None = None) -> Response:
    return templates.TemplateResponse(request, PAGE, {"active": "sets", **context}, block_name=block,
                                      status_code=status, headers=headers)


def _error(request: Request, exc: DriveBenchError) -> HTMLResponse:
    return HTMLResponse(error_fragment(problem_body(exc, str(request.url.path))), status_code=status_for(exc))


def _text(form: FormData, key: str) -> str:
    value = form.get(key)
    return value.strip() if isinstance(value, str) else ""


def _confirmation(request: Request, form: FormData) -> Confirmation | None:
    return confirmation(request, _text(form, "confirm") or None, _text(form, "confirm_values") or None)


def _version(form: FormData) -> int | None:
    text = _text(form, "version")
    if text and not text.isdigit():
        raise InvalidValue(_("The set's version {version} is not a number").format(version=repr(text)))
    return int(text) if text else None


def _target(form: FormData, key: str = "target") -> tuple[str, int]:
    """``demo-plant:5`` -> (session id, node id)."""
    session_id, _sep, node = _text(form, key).rpartition(":")
    if not session_id or not node.isdigit():
        raise InvalidValue(_("Choose a node"))
    return session_id, int(node)


def _nodes(manager: SessionManager) -> list[dict[str, Any]]:
    """Every node with a profile: what uploads, downloads and compares can address."""
    found = []
    for session in manager.list():
        for node in sorted(session.nodes.values(), key=lambda n: n.node_id):
            if node.profile is not None:
                found.append({"key": f"{session.id}:{node.node_id}", "session": session.name, "session_id": session.id,
                              "node_id": node.node_id, "device": node.device_name, "profile_id": node.profile.id})
    return found


def _source(key: str) -> SourceIn:
    """``set:3``, ``set:3:2`` (version 2), ``node:demo-plant:5``, ``defaults:<profile id>``."""
    kind, _sep, rest = key.partition(":")
    if kind == "set":
        set_id, _sep, version = rest.partition(":")
        if set_id.isdigit():
            return SourceIn(kind="set", set_id=int(set_id), version=int(version) if version.isdigit() else None)
    if kind == "node":
        session_id, _sep, node = rest.rpartition(":")
        if session_id and node.isdigit():
            return SourceIn(kind="node", session_id=session_id, node_id=int(node))
    if kind == "defaults" and rest:
        return SourceIn(kind="defaults", profile_id=rest)
    raise InvalidValue(_("Choose what to compare ('{key}' is not a source)").format(key=key))


def _page_context(state: AppState, manager: SessionManager, selected: int | None = None) -> dict[str, Any]:
    sets = store().all()
    nodes = _nodes(manager)
    profiles = sorted({s.profile_id for s in sets} | {n["profile_id"] for n in nodes})
    return {"sets": sets, "nodes": nodes, "profiles": profiles, "selected": selected,
            **audit_context(manager), "formats": set_formats.FORMATS}


# --- page and list -----------------------------------------------------------------------------------------
@router.get(UI, response_class=HTMLResponse)
async def sets_page(request: Request, state: StateDep, manager: ManagerDep, jobs: JobsDep,
                    set: int | None = None) -> Response:
    context = _page_context(state, manager, set)
    if set is not None:
        context.update(_detail(state, manager, set, jobs))
    return _render(request, None, context)


@router.get(UI + "/list", response_class=HTMLResponse)
async def sets_list(request: Request, state: StateDep, manager: ManagerDep) -> Response:
    return _render(request, "set_list", _page_context(state, manager))


@router.get(UI + "/sources", response_class=HTMLResponse)
async def compare_sources(request: Request, state: StateDep, manager: ManagerDep) -> Response:
    return _render(request, "compare_form", _page_context(state, manager))


# --- upload and import -------------------------------------------------------------------------------------
@router.post(UI + "/upload", response_class=HTMLResponse)
async def upload(request: Request, manager: ManagerDep, jobs: JobsDep, ctx: WriteCtxDep) -> Response:
    form = await request.form()
    try:
        session_id, node_id = _target(form)
        name = _text(form, "name") or _("Node {node}").format(node=node_id)
        job = set_jobs.start_upload(manager.get(session_id), node_id, jobs, store(), ctx=ctx, name=name,
                                    note=_text(form, "note"))
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "job", _job_context(job, jobs))


@router.post(UI + "/{set_id}/upload", response_class=HTMLResponse)
async def upload_version(request: Request, set_id: RowId, manager: ManagerDep, jobs: JobsDep,
                         ctx: WriteCtxDep) -> Response:
    form = await request.form()
    try:
        session_id, node_id = _target(form)
        job = set_jobs.start_upload(manager.get(session_id), node_id, jobs, store(), ctx=ctx, name="", into=set_id)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "job", _job_context(job, jobs))


@router.post(UI + "/import", response_class=HTMLResponse)
async def import_file(request: Request, state: StateDep) -> Response:
    form = await request.form()
    upload = form.get("file")
    if not isinstance(upload, UploadFile) or not upload.filename:
        return _error(request, InvalidValue(_("Choose a file (JSON, CSV or DCF)")))
    data = await upload.read(set_formats.MAX_SET_FILE_BYTES + 1)
    try:
        if len(data) > set_formats.MAX_SET_FILE_BYTES:
            raise InvalidValue(_("The file is larger than {size} MB").format(
                size=set_formats.MAX_SET_FILE_BYTES // 1024 // 1024))
        imported = set_formats.import_any(data, upload.filename, state.registry.get,
                                          profile_id=_text(form, "profile_id") or None,
                                          name=_text(form, "name") or None)
        stored = store().create(imported.name, imported.profile, imported.values, user=audit_user(request),
                                node_id=imported.node_id, note=imported.note,
                                reason=f"imported from {upload.filename}")
    except set_formats.SetImportError as exc:
        return _render(request, "import_errors", {"failure": exc}, status=422)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "import_done", {"stored": stored.info, "notes": imported.notes},
                   headers=CHANGED_EVENT)


# --- one set -----------------------------------------------------------------------------------------------
@router.get(UI + "/{set_id}", response_class=HTMLResponse)
async def set_detail(request: Request, set_id: RowId, state: StateDep, manager: ManagerDep, jobs: JobsDep) -> Response:
    try:
        context = _detail(state, manager, set_id, jobs)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "set_detail", context)


def _detail(state: AppState, manager: SessionManager, set_id: int, jobs: JobManager) -> dict[str, Any]:
    stored = store().get(set_id)
    profile = state.registry.get(stored.info.profile_id)
    targets = [n for n in _nodes(manager) if n["profile_id"] == profile.id]
    downloads = [download_out(row, jobs) for row in store().downloads(limit=500) if row.set_id == set_id][:10]
    return {"info": stored.info, "detail": detail_out(stored, profile), "history": store().history(set_id),
            "targets": targets, "formats": set_formats.FORMATS, "downloads": downloads}


@router.get(UI + "/{set_id}/downloads", response_class=HTMLResponse)
async def set_downloads(request: Request, set_id: RowId, state: StateDep, manager: ManagerDep,
                        jobs: JobsDep) -> Response:
    try:
        context = _detail(state, manager, set_id, jobs)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "downloads", context)


@router.post(UI + "/{set_id}/rename", response_class=HTMLResponse)
async def rename(request: Request, set_id: RowId, state: StateDep, manager: ManagerDep, jobs: JobsDep) -> Response:
    form = await request.form()
    try:
        # the version the page showed: a set changed meanwhile (another user, another server) is a 409 in words
        store().rename(set_id, _text(form, "name"), _text(form, "note"), base_version=_version(form))
        context = _detail(state, manager, set_id, jobs)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "set_detail", dict(context, saved=_("Saved")), headers=CHANGED_EVENT)


@router.delete(UI + "/{set_id}", response_class=HTMLResponse)
async def delete(request: Request, set_id: RowId) -> Response:
    try:
        store().delete(set_id)
    except DriveBenchError as exc:
        return _error(request, exc)
    return HTMLResponse(f'<p class="muted">{escape(_("Set deleted."))}</p>', headers=CHANGED_EVENT)


@router.post(UI + "/{set_id}/copy", response_class=HTMLResponse)
async def copy(request: Request, set_id: RowId, state: StateDep, manager: ManagerDep, jobs: JobsDep) -> Response:
    form = await request.form()
    try:
        wanted = _text(form, "to_node")
        if not wanted.isdigit() or not 1 <= int(wanted) <= 127:
            raise InvalidValue(_("The node id to copy to must be 1 ... 127"))
        to_node = int(wanted)
        stored = store().get(set_id)
        if stored.info.node_id is None:
            raise InvalidValue(_("The set was not uploaded from a node, so its node address is unknown"))
        profile = state.registry.get(stored.info.profile_id)
        values, notes = retarget(profile, stored.values, stored.info.node_id, to_node)
        copied = store().create(_("{name} (node {node})").format(name=stored.info.name, node=to_node), profile,
                                values, user=audit_user(request), node_id=to_node,
                                session_id=stored.info.session_id,
                                note=_("Copy of '{name}' v{version} for node {node}").format(
                                    name=stored.info.name, version=stored.version, node=to_node),
                                reason=f"copy of set {set_id} v{stored.version} for node {to_node}")
        context = _detail(state, manager, copied.info.id, jobs)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "set_detail", dict(context, copy_notes=notes or [_("No node-specific values to move")]),
                   headers=CHANGED_EVENT)


# --- download ----------------------------------------------------------------------------------------------
@router.post(UI + "/{set_id}/preview", response_class=HTMLResponse)
async def preview(request: Request, set_id: RowId, manager: ManagerDep, ctx: WriteCtxDep) -> Response:
    form = await request.form()
    try:
        session_id, node_id = _target(form)
        stored = store().get(set_id)
        lines = await set_jobs.preview(manager.get(session_id), node_id, stored, ctx=ctx)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "preview", {"info": stored.info, "lines": lines, "target": f"{session_id}:{node_id}",
                                        "node_id": node_id, "total": len(stored.values)})


@router.post(UI + "/{set_id}/download", response_class=HTMLResponse)
async def download(request: Request, set_id: RowId, manager: ManagerDep, jobs: JobsDep, ctx: WriteCtxDep
                   ) -> Response:
    form = await request.form()
    try:
        session_id, node_id = _target(form)
        session, stored = manager.get(session_id), store().get(set_id)
        held = await set_jobs.held_moving(session, node_id, set_jobs.download_targets(session, node_id, stored),
                                          ctx=ctx)
        job = set_jobs.start_download(session, node_id, jobs, store(), stored, ctx=ctx, held=held,
                                      save=form.get("save") == "on", confirm=_confirmation(request, form))
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "job", _job_context(job, jobs))


@router.post(UI + "/downloads/{download_id}/{action}", response_class=HTMLResponse)
async def follow_up(request: Request, download_id: int, action: str, manager: ManagerDep, jobs: JobsDep,
                    ctx: WriteCtxDep) -> Response:
    form = await request.form()
    try:
        row = store().download(download_id)
        session = manager.get(row.session_id)
        save = form.get("save") == "on"
        confirm = _confirmation(request, form)  # after the page's question, for sets that can move a drive
        if action == "retry":
            held = await set_jobs.held_moving(session, row.node_id, set_jobs.retry_targets(store(), download_id),
                                              ctx=ctx)
            job = set_jobs.start_retry(session, jobs, store(), download_id, ctx=ctx, save=save, confirm=confirm,
                                       held=held)
        elif action == "rollback":
            held = await set_jobs.held_moving(session, row.node_id, set_jobs.rollback_targets(store(), download_id),
                                              ctx=ctx)
            job = set_jobs.start_rollback(session, jobs, store(), download_id, ctx=ctx, save=save, confirm=confirm,
                                          held=held)
        else:
            raise InvalidValue(_("Unknown action '{action}'").format(action=action))
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "job", _job_context(job, jobs))


@router.get(UI + "/downloads/{download_id}", response_class=HTMLResponse)
async def stored_report(request: Request, download_id: int, jobs: JobsDep) -> Response:
    try:
        shown = download_out(store().download(download_id), jobs)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "report", {"download": shown, "report": shown.report, "notes": [],
                                       "state": shown.state, "outcome": shown.outcome, "error": None})


def _job_context(job: Job, jobs: JobManager) -> dict[str, Any]:
    out = set_job_out(job)
    context: dict[str, Any] = {"job": out, "report": out.report, "notes": out.notes, "download": None,
                               "state": out.download_state or out.state, "outcome": out.outcome, "error": out.error}
    download_id = job.result.get("download_id")
    if job.state.finished and download_id is not None:
        context["download"] = download_out(store().download(int(download_id)), jobs)
    return context


@router.get(UI + "/jobs/{job_id}", response_class=HTMLResponse)
async def job_state(request: Request, job_id: str, jobs: JobsDep) -> Response:
    try:
        job = jobs.get(job_id)
    except DriveBenchError as exc:
        return _error(request, exc)
    headers = None
    if job.state.finished:
        headers = CHANGED_EVENT if job.kind == "upload" else {"HX-Trigger": "downloads-changed"}
    return _render(request, "job", _job_context(job, jobs), headers=headers)


# --- compare -----------------------------------------------------------------------------------------------
async def _comparison(form: Any, state: AppState, manager: SessionManager, ctx: WriteContext) -> Any:
    body = CompareIn(left=_source(str(form.get("left") or "")), right=_source(str(form.get("right") or "")),
                     q=str(form.get("q") or ""))
    left, right = await build_sources(state, manager, body, ctx)
    return compare(left, right, query=body.q)


@router.post(UI + "/compare", response_class=HTMLResponse)
async def compare_view(request: Request, state: StateDep, manager: ManagerDep, ctx: WriteCtxDep) -> Response:
    form = await request.form()
    try:
        result = await _comparison(form, state, manager, ctx)
    except DriveBenchError as exc:
        return _error(request, exc)
    return _render(request, "compare_result", {"result": result, "left_key": form.get("left"),
                                               "right_key": form.get("right"), "q": form.get("q") or ""})


@router.get(UI + "/compare/export.csv")
async def compare_csv(request: Request, state: StateDep, manager: ManagerDep, ctx: WriteCtxDep) -> Response:
    result = await _comparison(request.query_params, state, manager, ctx)
    return Response(comparison_csv(result), media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="comparison.csv"'})

