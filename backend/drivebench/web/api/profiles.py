"""Device profiles: list, load errors, JSON schema, one profile, its entries (search), upload, delete, downloads.

Uploads are read as a stream and refused with 413 as soon as they pass ``max_upload_bytes`` (the body is never
spooled whole first); the file name is used for its suffix and in messages only, the stored file is named after
the profile id (see ``ProfileRegistry.add_upload``).
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import AsyncGenerator
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request, status
from fastapi.responses import HTMLResponse, JSONResponse, PlainTextResponse, Response
from pydantic import BaseModel
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser

from drivebench.config import settings
from drivebench.device.formats.eds import ImportWarning
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.xdd import XML_SUFFIXES
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.loader import LoadedFile, ProfileRegistry, shown_name
from drivebench.device.profiles.profile import ObjectEntry, Parameter, Profile, Value
from drivebench.device.profiles.profile_batch import MAX_FILES, add_many
from drivebench.errors import Conflict, DriveBenchError, ProfileError
from drivebench.i18n import N_, _, shown
from drivebench.web.deps import StateDep
from drivebench.web.problems import error_fragment, problem_body
from drivebench.web.state import AppState

router = APIRouter(prefix="/api/profiles", tags=["profiles"])

MULTIPART_OVERHEAD_BYTES = 64 * 1024
"""Room for the multipart boundaries and part headers around the file itself."""
MAX_PAGE = 500
EntryKind = Literal["all", "parameters", "objects"]


class UploadTooLarge(ProfileError):
    """An upload past the size limit: answered with 413 (Content Too Large), not 422."""

    title = N_("Upload too large")


# --- response models ------------------------------------------------------------------------------------
class ProfileSummary(BaseModel):
    id: str
    version: str
    family: str
    vendor: str
    product: str
    vendor_id: int | None
    product_code: int | None
    transport: str
    objects: int
    parameters: int
    builtin: bool
    source: str | None = None
    uploaded_as: str | None = None
    """The file name an uploaded profile came in as (shown only; it is stored as ``<id>.<suffix>``)."""
    warning_count: int = 0
    """How many quirks of the file the import read with a warning (``/api/profiles/{id}/warnings``)."""


class ImportWarningOut(BaseModel):
    """A quirk of a device description and the reading the import applied."""

    file: str
    line: int | None
    key: str | None
    message: str
    object: str | None
    """``0x6040sub0`` when the warning concerns one object."""
    limits: bool
    """The object's limits were repaired or dropped (a write of it says so first)."""


class UploadResult(ProfileSummary):
    warnings: list[ImportWarningOut]


class LoadError(BaseModel):
    """A profile file that did not load: which file, where in it, and why."""

    file: str
    line: int | None
    reason: str


class EntryRow(BaseModel):
    """One row of a profile's table: a vendor parameter (code/subcode) or a CANopen object (index/subindex)."""

    ref: str
    kind: Literal["parameter", "object"]
    code: str | None
    """The vendor code; for an object, the code that shows the same data (cross reference), if any."""
    subcode: int | None
    name: str
    index: str
    subindex: int
    parameter_set: int
    data_type: str
    access: str
    unit: str | None
    factor: int | float
    default: Value | None
    min: int | float | None
    max: int | float | None
    selection: dict[int, str]
    bits: dict[int, str]
    reset_required: bool
    pdo_mappable: bool
    group: str
    description: str | None
    limits_note: str | None = None
    """The file's LowLimit/HighLimit of this object were repaired or dropped on import: how."""


class BatchRowOut(BaseModel):
    """One file of a many-file upload: accepted, accepted with warnings, or refused (line and reason)."""

    file: str
    outcome: Literal["accepted", "warnings", "refused"]
    profile_id: str | None
    warnings: int
    line: int | None
    reason: str | None


class BatchResult(BaseModel):
    accepted: int
    with_warnings: int
    refused: int
    rows: list[BatchRowOut]


class EntryPage(BaseModel):
    profile: str
    q: str
    kind: EntryKind
    total: int
    offset: int
    limit: int
    items: list[EntryRow]


# --- what the API and the Profiles page share -----------------------------------------------------------
def summary(profile: Profile, registry: ProfileRegistry) -> ProfileSummary:
    return ProfileSummary(id=profile.id, version=profile.version, family=profile.family,
                          vendor=profile.identity.vendor_name, product=profile.identity.product_name,
                          vendor_id=profile.identity.vendor_id, product_code=profile.identity.product_code,
                          transport=profile.features.transport, objects=len(profile.objects),
                          parameters=len(profile.parameters), builtin=registry.is_builtin(profile.id),
                          source=profile.source, uploaded_as=registry.uploaded_as(profile.id),
                          warning_count=len(registry.loaded(profile.id).warnings))


def warning_out(warning: ImportWarning) -> ImportWarningOut:
    where = f"0x{warning.index:04X}sub{warning.subindex}" if warning.index is not None else None
    return ImportWarningOut(file=warning.file, line=warning.line, key=warning.key, message=shown(warning.message),
                            object=where, limits=warning.limits)


def upload_result(profile: Profile, registry: ProfileRegistry) -> UploadResult:
    warnings = [warning_out(w) for w in registry.loaded(profile.id).warnings]
    return UploadResult(**summary(profile, registry).model_dump(), warnings=warnings)


def split_location(file: str, message: str) -> LoadError:
    """``"x.eds:12: reason"`` (as ProfileError words it) -> file, line 12, reason."""
    rest = message[len(file) + 1:].lstrip() if message.startswith(file + ":") else message
    found = re.match(r"^(\d+):\s*(.*)$", rest, re.DOTALL)
    if found:
        return LoadError(file=file, line=int(found.group(1)), reason=found.group(2))
    return LoadError(file=file, line=None, reason=rest)


def load_errors(registry: ProfileRegistry) -> list[LoadError]:
    return [split_location(file, shown(message)) for file, message in registry.errors]


def upload_error(exc: ProfileError) -> LoadError:
    """Where an upload failed; ``file`` is empty when the upload was refused before its name was read."""
    detail = exc.shown_detail()
    return split_location(exc.source, detail) if exc.source else LoadError(file="", line=None, reason=detail)


_catalogs: dict[str, Catalog] = {}


def catalog_for(profile: Profile) -> Catalog:
    """One Catalog per loaded profile (rebuilt when an upload replaces the profile)."""
    cached = _catalogs.get(profile.id)
    if cached is None or cached.profile is not profile:
        cached = _catalogs[profile.id] = Catalog(profile)
    return cached


def entry_row(item: Item, loaded: LoadedFile | None = None) -> EntryRow:
    entry = item.entry
    is_parameter = isinstance(entry, Parameter)
    return EntryRow(
        ref=item.ref, kind="parameter" if is_parameter else "object",
        code=entry.code if isinstance(entry, Parameter | ObjectEntry) else None,
        subcode=entry.subcode if isinstance(entry, Parameter) else None,
        name=item.name, index=f"0x{item.index:04X}", subindex=item.subindex, parameter_set=item.parameter_set,
        data_type=entry.data_type.value, access=entry.access.value, unit=entry.unit, factor=entry.factor,
        default=entry.default, min=entry.min, max=entry.max, selection=entry.selection, bits=entry.bits,
        reset_required=entry.reset_required, pdo_mappable=entry.pdo_mappable, group=item.group,
        description=entry.description,
        limits_note=loaded.limits_note(item.index, item.subindex) if loaded and loaded.warnings else None)


def find_entries(profile: Profile, q: str, kind: EntryKind) -> list[Item]:
    """Entries matching ``q`` (code ``C00088``/``88``, name words, index ``0x5FA7``), exact match first."""
    items = catalog_for(profile).search(q)
    if kind == "parameters":
        return [i for i in items if isinstance(i.entry, Parameter)]
    if kind == "objects":
        return [i for i in items if not isinstance(i.entry, Parameter)]
    return items


def entry_page(profile: Profile, q: str, kind: EntryKind, offset: int, limit: int,
               loaded: LoadedFile | None = None) -> EntryPage:
    items = find_entries(profile, q, kind)
    rows = [entry_row(i, loaded) for i in items[offset:offset + limit]]
    return EntryPage(profile=profile.id, q=q, kind=kind, total=len(items), offset=offset, limit=limit, items=rows)


async def _capped(request: Request, cap: int, limit: int) -> AsyncGenerator[bytes, None]:
    received = 0
    async for chunk in request.stream():
        received += len(chunk)
        if received > cap:
            raise UploadTooLarge(_("the upload is larger than the limit of {limit}").format(limit=_size(limit)))
        yield chunk


def _size(count: int) -> str:
    return f"{count / 1024 / 1024:.1f} MiB" if count >= 1024 * 1024 else f"{count / 1024:.0f} KiB"


async def read_upload(request: Request, limit: int) -> tuple[str, bytes]:
    """The file of a multipart upload (field ``file``): its name and bytes. Raises UploadTooLarge as soon as the
    declared or received size passes ``limit``, ProfileError when no file came."""
    cap = limit + MULTIPART_OVERHEAD_BYTES
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > cap:
        raise UploadTooLarge(_("the upload is {size}, more than the limit of {limit}").format(
            size=_size(int(declared)), limit=_size(limit)))
    if not request.headers.get("content-type", "").startswith("multipart/form-data"):
        raise ProfileError(_("send the profile file as multipart/form-data in the field 'file'"))
    parser = MultiPartParser(request.headers, _capped(request, cap, limit), max_files=1, max_fields=20)
    try:
        form = await parser.parse()
    except MultiPartException as exc:
        raise ProfileError(_("the upload is not a readable form: {reason}").format(reason=exc.message)) from exc
    try:
        upload = form.get("file")
        if not isinstance(upload, UploadFile):
            raise ProfileError(_("no file in the upload: choose an EDS, DCF or JSON file (form field 'file')"))
        name = shown_name(upload.filename or "upload")
        content = await upload.read(limit + 1)
        if len(content) > limit:
            raise UploadTooLarge(_("the file is larger than the limit of {limit}").format(limit=_size(limit)),
                                 source=name)
        return name, content
    finally:
        await form.close()


async def read_uploads(request: Request, limit: int) -> list[tuple[str, bytes]]:
    """The files of a multipart upload with several files (field ``files``, or ``file``). Raises UploadTooLarge
    past ``limit`` in all, ProfileError for too many files or none."""
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit + MULTIPART_OVERHEAD_BYTES:
        raise UploadTooLarge(_("the upload is {size}, more than the limit of {limit} for many files at once").format(
            size=_size(int(declared)), limit=_size(limit)))
    if not request.headers.get("content-type", "").startswith("multipart/form-data"):
        raise ProfileError(_("send the files as multipart/form-data in the field 'files'"))
    parser = MultiPartParser(request.headers, _capped(request, limit + MULTIPART_OVERHEAD_BYTES, limit),
                             max_files=MAX_FILES, max_fields=20)
    try:
        form = await parser.parse()
    except MultiPartException as exc:
        raise ProfileError(_("the upload is not a readable form: {reason} (at most {limit} files at once)").format(
            reason=exc.message, limit=MAX_FILES)) from exc
    try:
        uploads = [u for key in ("files", "file") for u in form.getlist(key) if isinstance(u, UploadFile)]
        if not uploads:
            raise ProfileError(_("no file in the upload: choose EDS, DCF, XDD, XDC, JSON files or a .zip (field "
                                 "'files')"))
        return [(shown_name(u.filename or "upload"), await u.read()) for u in uploads]
    finally:
        await form.close()


async def store_many(request: Request, state: AppState) -> BatchResult:
    """Read and store several files or zips; each file is accepted or refused on its own."""
    uploads = await read_uploads(request, settings.max_batch_upload_bytes)
    rows = await asyncio.to_thread(add_many, state.registry, uploads)
    out = [BatchRowOut(**vars(row)) for row in rows]
    return BatchResult(accepted=sum(r.outcome == "accepted" for r in out),
                       with_warnings=sum(r.outcome == "warnings" for r in out),
                       refused=sum(r.outcome == "refused" for r in out), rows=out)


async def store_upload(request: Request, state: AppState) -> Profile:
    """Read, check and store an uploaded profile; a bad file changes nothing."""
    registry = state.registry
    name, content = await read_upload(request, registry.max_upload_bytes)
    if name.lower().endswith(".json"):
        _check_utf8(content, name)
    return await asyncio.to_thread(registry.add_upload, name, content)


def _check_utf8(content: bytes, name: str) -> None:
    """JSON must be UTF-8: name the line of the first bad byte (pydantic only says 'invalid unicode')."""
    try:
        content.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = content.count(b"\n", 0, exc.start) + 1
        raise ProfileError(_("not UTF-8 text: byte {byte} cannot be decoded").format(
            byte=f"0x{content[exc.start]:02X}"), source=name, line=line) from exc


def users_of(state: AppState, profile_id: str) -> list[str]:
    """Nodes of open sessions handled with this profile (``node 5 of 'Demo plant'``)."""
    return [_("node {node} of '{session}'").format(node=node_id, session=session.name)
            for session in state.manager.list()
            for node_id, node in session.nodes.items() if node.profile is not None and node.profile.id == profile_id]


async def delete_upload(state: AppState, profile_id: str) -> None:
    registry = state.registry
    registry.get(profile_id)
    if registry.is_builtin(profile_id):
        raise Conflict(_("'{profile}' is a built-in profile (device_profiles/); only uploaded profiles can be "
                         "deleted").format(profile=profile_id))
    in_use = users_of(state, profile_id)
    if in_use:
        raise Conflict(_("'{profile}' is in use by {nodes}; remove those nodes first").format(
            profile=profile_id, nodes=", ".join(in_use)))
    await asyncio.to_thread(registry.remove_upload, profile_id)


def problem_response(request: Request, exc: DriveBenchError, status_code: int) -> Response:
    """A problem+json (or, for htmx, an error fragment) with a status the shared table does not give."""
    body = problem_body(exc, str(request.url.path))
    body["status"] = status_code
    if request.headers.get("HX-Request") == "true":
        return HTMLResponse(error_fragment(body), status_code=status_code)
    return JSONResponse(body, status_code=status_code, media_type="application/problem+json")


def _attachment(filename: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{filename}"'}


# --- routes ---------------------------------------------------------------------------------------------
@router.get("", response_model=list[ProfileSummary])
async def list_profiles(state: StateDep) -> list[ProfileSummary]:
    return [summary(p, state.registry) for p in state.registry.all()]


@router.get("/load-errors", response_model=list[LoadError])
async def list_load_errors(state: StateDep) -> list[LoadError]:
    """Profile files in the built-in and upload directories that did not load, with line and reason."""
    return load_errors(state.registry)


@router.get("/schema")
async def profile_schema() -> dict[str, Any]:
    """The JSON schema of a profile file (device_profiles/*.json)."""
    return ProfileRegistry.json_schema()


@router.get("/{profile_id}", response_model=Profile)
async def get_profile(profile_id: str, state: StateDep) -> Profile:
    return state.registry.get(profile_id)


@router.get("/{profile_id}/parameters", response_model=EntryPage)
async def search_parameters(profile_id: str, state: StateDep, q: str = "", kind: EntryKind = "all",
                            offset: Annotated[int, Query(ge=0)] = 0,
                            limit: Annotated[int, Query(ge=1, le=MAX_PAGE)] = 100) -> EntryPage:
    """Vendor parameters and CANopen objects matching ``q``: a code (``C00088``, ``88``, ``C00118/3``), words of
    the name, or an index (``0x5FA7``, ``0x1018.1``). The exact match of a code or index comes first."""
    loaded = state.registry.loaded(profile_id)
    return await asyncio.to_thread(entry_page, loaded.profile, q, kind, offset, limit, loaded)


@router.get("/{profile_id}/warnings", response_model=list[ImportWarningOut])
async def get_profile_warnings(profile_id: str, state: StateDep) -> list[ImportWarningOut]:
    """The quirks of the profile's file and the reading the import applied to each (file, line, key)."""
    return [warning_out(w) for w in state.registry.loaded(profile_id).warnings]


@router.get("/{profile_id}/eds", response_class=Response,
            responses={200: {"content": {"text/plain": {}}, "description": "The EDS/DCF file"}})
async def get_profile_eds(profile_id: str, state: StateDep, regenerate: bool = False) -> Response:
    """The profile as EDS: an EDS/DCF file exactly as it was loaded (byte for byte), else (or with
    ``regenerate=true``) written from the profile."""
    loaded = state.registry.loaded(profile_id)
    if loaded.original is not None and loaded.suffix in (".eds", ".dcf") and not regenerate:
        return Response(loaded.original, media_type="application/octet-stream",
                        headers=_attachment(f"{profile_id}{loaded.suffix}"))
    return PlainTextResponse(export_eds(loaded.profile), headers=_attachment(f"{profile_id}.eds"))


@router.get("/{profile_id}/xdd", response_class=Response,
            responses={200: {"content": {"application/xml": {}}, "description": "The XDD/XDC file"}})
async def get_profile_xdd(profile_id: str, state: StateDep, regenerate: bool = False) -> Response:
    """The profile as CiA 311 XDD: an XDD/XDC file exactly as it was loaded, else (or with ``regenerate=true``)
    written from the profile."""
    loaded = state.registry.loaded(profile_id)
    if loaded.original is not None and loaded.suffix in XML_SUFFIXES and not regenerate:
        return Response(loaded.original, media_type="application/xml",
                        headers=_attachment(f"{profile_id}{loaded.suffix}"))
    return Response(export_xdd(loaded.profile), media_type="application/xml",
                    headers=_attachment(f"{profile_id}.xdd"))


@router.get("/{profile_id}/json", response_class=Response,
            responses={200: {"content": {"application/json": {}}, "description": "The profile file"}})
async def get_profile_json(profile_id: str, state: StateDep) -> Response:
    profile = state.registry.get(profile_id)
    return Response(profile.model_dump_json(indent=2) + "\n", media_type="application/json",
                    headers=_attachment(f"{profile.id}.json"))


UPLOAD_BODY = {"requestBody": {"required": True, "content": {"multipart/form-data": {"schema": {
    "type": "object", "required": ["file"],
    "properties": {"file": {"type": "string", "format": "binary", "description": "An .eds, .dcf or .json file"}}}}}}}


@router.post("", response_model=UploadResult, status_code=status.HTTP_201_CREATED, openapi_extra=UPLOAD_BODY,
             responses={413: {"description": "The file is larger than the upload limit"},
                        422: {"description": "The file is not a valid profile (problem+json with source, line)"}})
async def upload_profile(request: Request, state: StateDep) -> UploadResult | Response:
    """Upload an EDS, DCF or JSON profile. Quirks of the file are read and listed in ``warnings``; a file without
    a usable object dictionary is refused with file name, line and reason."""
    try:
        profile = await store_upload(request, state)
    except UploadTooLarge as exc:
        return problem_response(request, exc, status.HTTP_413_CONTENT_TOO_LARGE)
    return upload_result(profile, state.registry)


@router.post("/batch", response_model=BatchResult, openapi_extra={"requestBody": {"required": True, "content": {
    "multipart/form-data": {"schema": {"type": "object", "required": ["files"], "properties": {"files": {
        "type": "array", "items": {"type": "string", "format": "binary"},
        "description": "EDS, DCF, XDD, XDC or JSON files, or .zip archives of them"}}}}}}},
             responses={413: {"description": "More than 64 MiB sent at once"},
                        422: {"description": "Too many files, none, or not a form (problem+json)"}})
async def upload_many(request: Request, state: StateDep) -> BatchResult | Response:
    """Upload several device descriptions or a .zip of a vendor's folder. Every file is checked on its own: the
    summary says which were accepted, accepted with warnings, or refused (file, line, reason)."""
    try:
        return await store_many(request, state)
    except UploadTooLarge as exc:
        return problem_response(request, exc, status.HTTP_413_CONTENT_TOO_LARGE)


@router.delete("/{profile_id}", status_code=status.HTTP_204_NO_CONTENT,
               responses={409: {"description": "Built-in profiles cannot be deleted"}})
async def delete_profile(profile_id: str, state: StateDep) -> Response:
    """Delete an uploaded profile (built-in ones answer 409)."""
    await delete_upload(state, profile_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
