"""Device profiles over HTTP: list, load errors, JSON schema, one profile, its entries (search), upload, delete,
downloads. What they do lives in :mod:`drivebench.services.profiles`; reading the upload in
:mod:`drivebench.web.profile_uploads`.
"""

from __future__ import annotations

import asyncio
import json
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Request, status
from fastapi.responses import HTMLResponse, JSONResponse, Response

from drivebench.device.formats.xdd import XML_SUFFIXES
from drivebench.device.formats.xdd_export import export_warnings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Profile
from drivebench.errors import DriveBenchError, UnknownParameter
from drivebench.i18n import _
from drivebench.services.profiles.edit import ObjectEdit, edit_object, regenerated_eds, regenerated_xdd
from drivebench.services.profiles.store import BatchResult, UploadTooLarge, delete_upload
from drivebench.services.profiles.views import (
    EntryKind,
    EntryPage,
    ImportWarningOut,
    LoadError,
    ProfileSummary,
    UploadResult,
    entry_page,
    load_errors,
    summary,
    upload_result,
    warning_out,
)
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import StateDep, wait_for_profiles
from drivebench.web.problems import error_fragment, problem_body
from drivebench.web.profile_uploads import receive_many, receive_upload

router = APIRouter(route_class=DeferredRoute, prefix="/api/profiles", tags=["profiles"],
                   dependencies=[Depends(wait_for_profiles)])

MAX_PAGE = 500


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
    ``regenerate=true``) written from the profile; one read from an EDS/DCF is written over that file, so only
    what was edited differs from it."""
    loaded = state.registry.loaded(profile_id)
    if loaded.original is not None and loaded.suffix in (".eds", ".dcf") and not regenerate:
        return Response(loaded.original, media_type="application/octet-stream",
                        headers=_attachment(f"{profile_id}{loaded.suffix}"))
    content, media_type = await asyncio.to_thread(regenerated_eds, loaded)
    return Response(content, media_type=media_type, headers=_attachment(f"{profile_id}.eds"))


@router.get("/{profile_id}/xdd", response_class=Response,
            responses={200: {"content": {"application/xml": {}}, "description": "The XDD/XDC file"}})
async def get_profile_xdd(profile_id: str, state: StateDep, regenerate: bool = False) -> Response:
    """The profile as CiA 311 XDD: an XDD/XDC file exactly as it was loaded, else (or with ``regenerate=true``)
    written from the profile; one read from an XDD/XDC is written over that file's XML tree, so only what was
    edited differs from it."""
    loaded = state.registry.loaded(profile_id)
    if loaded.original is not None and loaded.suffix in XML_SUFFIXES and not regenerate:
        return Response(loaded.original, media_type="application/xml",
                        headers=_attachment(f"{profile_id}{loaded.suffix}"))
    warnings = export_warnings(loaded.profile)  # EDS keys without a CiA 311 place (kept as EDS: properties)
    headers = _attachment(f"{profile_id}.xdd") | (
        {"X-DriveBench-Export-Warnings": json.dumps(warnings)} if warnings else {})
    content = await asyncio.to_thread(regenerated_xdd, loaded)
    return Response(content, media_type="application/xml", headers=headers)


@router.patch("/{profile_id}/objects/{index}/{subindex}", response_model=Profile,
              responses={409: {"description": "Not an uploaded EDS/DCF/XDD/XDC profile"},
                         422: {"description": "Not an object of the profile, or a value that does not fit it"}})
async def patch_object(profile_id: str, index: str, subindex: int, edit: ObjectEdit, state: StateDep) -> Profile:
    """Edit one object of an uploaded EDS/DCF/XDD/XDC profile (``index`` hex as ``0x2000`` or ``2000``): the stored
    file is written over, only the keys (XDD: attributes, elements) of the edit change."""
    try:
        number = int(index, 16)
    except ValueError:
        raise UnknownParameter(_("{index!r} is no object index (hex, as 0x2000)").format(index=index)) from None
    return await asyncio.to_thread(edit_object, state.registry, profile_id, number, subindex, edit)


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
        profile = await receive_upload(request, state)
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
        return await receive_many(request, state)
    except UploadTooLarge as exc:
        return problem_response(request, exc, status.HTTP_413_CONTENT_TOO_LARGE)


@router.delete("/{profile_id}", status_code=status.HTTP_204_NO_CONTENT,
               responses={409: {"description": "Built-in profiles cannot be deleted"}})
async def delete_profile(profile_id: str, state: StateDep) -> Response:
    """Delete an uploaded profile (built-in ones answer 409)."""
    await delete_upload(state.registry, state.manager.list(), profile_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
