"""Profile files out of a multipart request, shared by the API and the Profiles page.

Uploads are read as a stream and refused with 413 as soon as they pass the limit (the body is never spooled whole
first); the file name is used for its suffix and in messages only, the stored file is named after the profile id
(see ``ProfileRegistry.add_upload``).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncGenerator

from fastapi import Request
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser

from drivebench.config import settings
from drivebench.device.profiles.loader import shown_name
from drivebench.device.profiles.profile import Profile
from drivebench.device.profiles.profile_batch import MAX_FILES
from drivebench.errors import ProfileError
from drivebench.i18n import _
from drivebench.services.profiles.store import BatchResult, UploadTooLarge, size_text, store_many, store_upload
from drivebench.web.state import AppState

MULTIPART_OVERHEAD_BYTES = 64 * 1024
"""Room for the multipart boundaries and part headers around the file itself."""


async def _capped(request: Request, cap: int, limit: int) -> AsyncGenerator[bytes, None]:
    received = 0
    async for chunk in request.stream():
        received += len(chunk)
        if received > cap:
            raise UploadTooLarge(_("the upload is larger than the limit of {limit}").format(limit=size_text(limit)))
        yield chunk


async def read_upload(request: Request, limit: int) -> tuple[str, bytes]:
    """The file of a multipart upload (field ``file``): its name and bytes. Raises UploadTooLarge as soon as the
    declared or received size passes ``limit``, ProfileError when no file came."""
    cap = limit + MULTIPART_OVERHEAD_BYTES
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > cap:
        raise UploadTooLarge(_("the upload is {size}, more than the limit of {limit}").format(
            size=size_text(int(declared)), limit=size_text(limit)))
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
            raise UploadTooLarge(_("the file is larger than the limit of {limit}").format(limit=size_text(limit)),
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
            size=size_text(int(declared)), limit=size_text(limit)))
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


async def receive_upload(request: Request, state: AppState) -> Profile:
    """Read, check and store an uploaded profile; a bad file changes nothing."""
    registry = state.registry
    name, content = await read_upload(request, registry.max_upload_bytes)
    return await asyncio.to_thread(store_upload, registry, name, content)


async def receive_many(request: Request, state: AppState) -> BatchResult:
    """Read and store several files or zips; each file is accepted or refused on its own."""
    uploads = await read_uploads(request, settings.max_batch_upload_bytes)
    return await asyncio.to_thread(store_many, state.registry, uploads)
