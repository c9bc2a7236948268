"""The Profiles screen: every device profile, upload (EDS/DCF/JSON), one profile with its searchable entries."""

from __future__ import annotations

from typing import Annotated, Any
from urllib.parse import urlencode

from fastapi import APIRouter, Depends, Query, Request, status
from fastapi.responses import HTMLResponse, Response

from drivebench.device.formats.xdd import XML_SUFFIXES
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.loader import LoadedFile
from drivebench.device.profiles.profile import Value
from drivebench.errors import DriveBenchError, ProfileError
from drivebench.services.profiles.edit import is_editable
from drivebench.services.profiles.loading import progress_line
from drivebench.services.profiles.store import UploadTooLarge, delete_upload
from drivebench.services.profiles.views import EntryKind, entry_page, load_errors, summary, upload_error, warning_out
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import StateDep, wait_for_profiles
from drivebench.web.pages.node_info import identity_text
from drivebench.web.problems import status_for
from drivebench.web.profile_uploads import receive_many, receive_upload
from drivebench.web.root import under_root
from drivebench.web.state import AppState, app_state
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False, dependencies=[Depends(wait_for_profiles)])
templates.env.filters["device_type"] = lambda raw: identity_text("0x1000", raw)


def limits_note(request: Request, profile_id: str | None, item: Item) -> str | None:
    """What the import of the profile's file did to this item's limits (a parameter row says it before a write)."""
    registry = app_state(request.app).registry
    if profile_id is None:
        return None
    try:
        loaded: LoadedFile = registry.loaded(profile_id)
    except DriveBenchError:
        return None
    return loaded.limits_note(item.index, item.subindex) if loaded.warnings else None


templates.env.globals["limits_note"] = limits_note

PAGE_SIZE = 100
TYPE_SHORT = {"BOOLEAN": "BOOL", "VISIBLE_STRING": "VSTR", "OCTET_STRING": "OSTR", "UNICODE_STRING": "USTR"}


class Show:
    """How the entries table words values: engineering units with the factor's decimals, texts for lists."""

    @staticmethod
    def decimals(factor: float) -> int:
        digits = 0
        while factor >= 10 and digits < 6:
            factor /= 10
            digits += 1
        return digits

    @staticmethod
    def number(value: Value | None, factor: float = 1, *, trim: bool = False) -> str:
        """``10.2`` with factor 100 -> ``10.20`` (the resolution shows); ``trim`` drops trailing zeros."""
        if value is None:
            return ""
        if isinstance(value, str):
            return value
        digits = Show.decimals(float(factor))
        text = f"{value:.{digits}f}" if digits else (str(int(value)) if float(value).is_integer() else f"{value:g}")
        return text.rstrip("0").rstrip(".") if trim and "." in text else text

    @staticmethod
    def value(value: Value | None, factor: float, selection: dict[int, str]) -> str:
        text = Show.number(value, factor)
        if isinstance(value, int | float) and float(value).is_integer() and int(value) in selection:
            return f"{text} · {selection[int(value)]}"
        return text

    @staticmethod
    def range(low: float | None, high: float | None, factor: float) -> str:
        if low is None and high is None:
            return ""
        if high is None:
            return f"≥ {Show.number(low, factor, trim=True)}"
        if low is None:
            return f"≤ {Show.number(high, factor, trim=True)}"
        return f"{Show.number(low, factor, trim=True)} … {Show.number(high, factor, trim=True)}"

    @staticmethod
    def data_type(name: str) -> str:
        if name in TYPE_SHORT:
            return TYPE_SHORT[name]
        for long, short in (("UNSIGNED", "U"), ("INTEGER", "I")):
            if name.startswith(long):
                return short + name[len(long):]
        return name

    @staticmethod
    def choices(choices: dict[int, str], sep: str = " · ") -> str:
        return sep.join(f"{raw} {text}" for raw, text in sorted(choices.items()))


def _list_context(state: AppState, **extra: Any) -> dict[str, Any]:
    registry = state.registry
    summaries = [summary(p, registry) for p in registry.all()]
    return {"active": "profiles", "profiles": summaries, "load_errors": load_errors(registry),
            "builtin_count": sum(1 for s in summaries if s.builtin), "limit_mib": registry.max_upload_bytes / 2**20,
            "loading_line": progress_line(registry), **extra}


def _list_block(request: Request, state: AppState, status_code: int = 200, **extra: Any) -> Response:
    return templates.TemplateResponse(request, "profiles.html", _list_context(state, **extra),
                                      block_name="profiles_body", status_code=status_code)


@router.get("/profiles", response_class=HTMLResponse)
async def profiles_page(request: Request, state: StateDep) -> Response:
    return templates.TemplateResponse(request, "profiles.html", _list_context(state))


@router.post("/ui/profiles", response_class=HTMLResponse)
async def upload(request: Request, state: StateDep) -> Response:
    """Upload from the form: the list and the form come back, with the error beside the form if the file is bad."""
    try:
        profile = await receive_upload(request, state)
    except ProfileError as exc:
        return _refused(request, state, exc)
    return _list_block(request, state, upload_ok=profile.id,
                       upload_warnings=len(state.registry.loaded(profile.id).warnings))


def _refused(request: Request, state: AppState, exc: ProfileError) -> Response:
    """The list and the form again, with why the upload was refused beside the form."""
    code = status.HTTP_413_CONTENT_TOO_LARGE if isinstance(exc, UploadTooLarge) else status_for(exc)
    return _list_block(request, state, code, upload_error=upload_error(exc), upload_title=exc.title)


@router.post("/ui/profiles/batch", response_class=HTMLResponse)
async def upload_batch(request: Request, state: StateDep) -> Response:
    """Several files or a zip from the form: the list comes back with the summary table of every file."""
    try:
        result = await receive_many(request, state)
    except ProfileError as exc:
        return _refused(request, state, exc)
    return _list_block(request, state, batch=result)


@router.post("/ui/profiles/{profile_id}/delete", response_class=HTMLResponse)
async def delete(request: Request, state: StateDep, profile_id: str,
                 where: Annotated[str, Query(pattern="^(list|detail)$")] = "list") -> Response:
    await delete_upload(state.registry, state.manager.list(), profile_id)
    if where == "detail":
        return Response(headers={"HX-Redirect": under_root(request.scope, "/profiles")})
    return _list_block(request, state, deleted=profile_id)


def _entries_context(loaded: LoadedFile, q: str, kind: EntryKind, offset: int, editable: bool) -> dict[str, Any]:
    profile = loaded.profile
    page = entry_page(profile, q, kind, offset, PAGE_SIZE, loaded)
    shown = page.offset + len(page.items)
    query = {k: v for k, v in (("q", q), ("kind", kind)) if v and v != "all"}
    more_url = f"/profiles/{profile.id}/entries?" + urlencode({**query, "offset": shown})
    return {"profile": profile, "page": page, "rows": page.items, "more_url": more_url,
            "remaining": page.total - shown, "page_size": PAGE_SIZE, "show": Show, "editable": editable,
            "file_kind": "XDD" if loaded.suffix in XML_SUFFIXES else "EDS"}


@router.get("/profiles/{profile_id}", response_class=HTMLResponse)
async def profile_page(request: Request, state: StateDep, profile_id: str, q: str = "",
                       kind: EntryKind = "all") -> Response:
    loaded = state.registry.loaded(profile_id)
    profile = loaded.profile
    context = {"active": "profiles", "summary": summary(profile, state.registry),
               "counts": {"parameters": len(profile.parameters), "objects": len(profile.objects)},
               "import_warnings": [warning_out(w) for w in loaded.warnings],
               **_entries_context(loaded, q, kind, 0, is_editable(state.registry, profile_id))}
    return templates.TemplateResponse(request, "profiles.html", {**context, "detail": True})


@router.get("/profiles/{profile_id}/entries", response_class=HTMLResponse)
async def entries(request: Request, state: StateDep, profile_id: str, q: str = "", kind: EntryKind = "all",
                  offset: Annotated[int, Query(ge=0)] = 0) -> Response:
    """The entries table for a search (offset 0), or the next rows for 'show more'."""
    loaded = state.registry.loaded(profile_id)
    profile = loaded.profile
    context = _entries_context(loaded, q, kind, offset, is_editable(state.registry, profile_id))
    response = templates.TemplateResponse(request, "profiles.html", context,
                                          block_name="entries" if offset == 0 else "entry_rows")
    if offset == 0:
        query = urlencode({k: v for k, v in (("q", q), ("kind", kind)) if v and v != "all"})
        response.headers["HX-Replace-Url"] = f"/profiles/{profile.id}" + (f"?{query}" if query else "")
    return response
