"""Errors as RFC 9457 problem details: one table from error class to HTTP status, one handler.

JSON clients get ``application/problem+json``; htmx requests get an error partial with the same status, so
the page shows the error next to the action that caused it; a browser opening a page gets the problem as a page
of the app (navigation bar, a way back), same status.
"""

from __future__ import annotations

import json
import logging

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from markupsafe import Markup
from sqlalchemy.exc import InterfaceError, OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException

from drivebench import errors
from drivebench.i18n import N_, _
from drivebench.services.storage import reachability
from drivebench.web.root import route_path
from drivebench.web.templating import templates

log = logging.getLogger(__name__)

# Most specific class first.
STATUS: list[tuple[type[errors.DriveBenchError], int]] = [
    (errors.UnknownParameter, 404),
    (errors.UnknownProfile, 404),
    (errors.NotFound, 404),
    (errors.OutOfRange, 422),
    (errors.InvalidValue, 422),
    (errors.ReadOnly, 422),
    (errors.ProfileError, 422),
    (errors.BusSpecError, 422),
    (errors.ParameterError, 422),
    (errors.Conflict, 409),
    (errors.ContentTooLarge, 413),
    (errors.DatabaseUnavailable, 503),
    (errors.SchemaTooNew, 503),
    (errors.ConfirmationRequired, 428),
    (errors.NotAuthenticated, 401),
    (errors.AccessDenied, 403),
    (errors.SdoTimeoutError, 504),
    (errors.NodeOffline, 504),
    (errors.AdapterUnavailable, 503),
    (errors.TransportError, 503),
    (errors.ProtocolError, 502),
    (errors.DriveBenchError, 400),
]


def status_for(exc: errors.DriveBenchError) -> int:
    if isinstance(exc, errors.SdoAbortError) and exc.abort_code in (0x06020000, 0x06090011):
        return 404
    if isinstance(exc, errors.SdoAbortError) and exc.abort_code in (0x06090030, 0x06090031, 0x06090032,
                                                                    0x06010002, 0x06040043):
        return 422
    for cls, status in STATUS:
        if isinstance(exc, cls):
            return status
    return 500


def problem_body(exc: errors.DriveBenchError, instance: str) -> dict[str, object]:
    type_name = type(exc).__name__
    kebab = "".join("-" + c.lower() if c.isupper() else c for c in type_name).lstrip("-")
    body: dict[str, object] = {
        "type": f"/problems/{kebab}",
        "title": _(exc.title),  # the request's language (web/language): English unless the browser asks German
        "status": status_for(exc),
        "detail": exc.shown_detail(),
        "instance": instance,
    }
    body.update({k: v for k, v in exc.extra().items() if v is not None})
    if exc.hint:
        body["hint"] = exc.shown_hint()  # a Text or N_() hint in the reader's words; any other stays as it is
    return body


def error_fragment(body: dict[str, object]) -> Markup:
    """The problem as the pages' error box; Markup.format escapes every value (titles and details may name a lease
    holder, a profile's texts or a file name), so templates put it in as it is, without ``|safe``."""
    parts = [Markup("<strong>{}</strong> {}").format(body["title"], body["detail"])]
    if "abort_code" in body and str(body["abort_code"]) not in str(body["detail"]):  # not twice
        parts.append(Markup('<code class="abort">{} {}</code>').format(body["abort_code"], body.get("abort_text", "")))
    if body.get("hint"):
        parts.append(Markup('<div class="hint">{}</div>').format(body["hint"]))
    if "confirm_node" in body:  # a 428: the page's dialog (app.js) is built from these, not from the sentence
        asks = Markup('<div class="error" role="alert" data-confirm-node="{}" data-confirm-values="{}">{}</div>')
        return asks.format(body["confirm_node"], json.dumps(body.get("confirm_values") or {}, sort_keys=True),
                           Markup(" ").join(parts))
    return Markup('<div class="error" role="alert">{}</div>').format(Markup(" ").join(parts))


def wants_page(request: Request) -> bool:
    """A browser opening a page (not htmx, not the JSON API, not a script's fetch)."""
    return (request.method == "GET" and request.headers.get("HX-Request") != "true"
            and "text/html" in request.headers.get("accept", "")
            and not route_path(request.scope).startswith(("/api/", "/ws/", "/static/")))


# Where to go from a failed page, by the start of its path; the Plant screen lists sessions and nodes.
WAYS_BACK = [("/profiles/", "/profiles", N_("All profiles")),
             ("/parameter-sets/", "/parameter-sets", N_("All parameter sets")),
             ("/monitor/", "/monitor", N_("Monitor")), ("/sessions/", "/", N_("Plant: sessions and nodes"))]


def error_page(request: Request, body: dict[str, object]) -> Response:
    path = route_path(request.scope)
    context: dict[str, object] = {"problem": body, "active": None}
    if path.startswith("/remote/"):  # a share link's viewer: no navigation into the engineer's screens
        context["viewer"] = None
        context["ways"] = []
    else:
        ways = [(href, _(label)) for prefix, href, label in WAYS_BACK if path.startswith(prefix)]
        context["ways"] = ways if any(href == "/" for href, _label in ways) else [*ways, ("/", _("Plant"))]
    status = int(body["status"])  # type: ignore[call-overload]
    return templates.TemplateResponse(request, "error.html", context, status_code=status)


def install(app: FastAPI) -> None:
    @app.exception_handler(errors.DriveBenchError)
    async def _drivebench_error(request: Request, exc: errors.DriveBenchError) -> Response:
        return _problem(request, exc)

    @app.exception_handler(OperationalError)
    @app.exception_handler(InterfaceError)
    async def _database_error(request: Request, exc: Exception) -> Response:
        """The database went away while the server runs: 503 in words (one log line, no traceback per request)."""
        problem = reachability.unavailable(exc)
        log.warning("%s %s: %s", request.method, request.url.path, problem.detail)
        return _problem(request, problem)

    def _problem(request: Request, exc: errors.DriveBenchError) -> Response:
        body = problem_body(exc, str(request.url.path))
        status = int(body["status"])  # type: ignore[call-overload]
        if request.headers.get("HX-Request") == "true":
            return HTMLResponse(error_fragment(body), status_code=status)
        if wants_page(request):
            return error_page(request, body)
        return JSONResponse(body, status_code=status, media_type="application/problem+json")

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> Response:
        """Unknown URLs and methods: FastAPI's JSON for clients, a page of the app for a browser."""
        if not wants_page(request):
            return await http_exception_handler(request, exc)
        missing = _("There is no page at {path}.").format(path=request.url.path)
        detail = exc.detail if exc.status_code != 404 else missing
        title = _("Page not found") if exc.status_code == 404 else _("Request failed")
        body: dict[str, object] = {"type": "about:blank", "title": title, "status": exc.status_code,
                                   "detail": detail, "instance": request.url.path}
        return error_page(request, body)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> Response:
        # What was submitted is not echoed: it may be a password (a 422 lands in logs, proxies, screenshots).
        errors = [{k: v for k, v in e.items() if k not in ("input", "ctx")} for e in exc.errors()]
        problems = [f"{'.'.join(str(p) for p in e['loc'] if p != 'body')}: {e['msg']}" for e in errors]
        body = {"type": "/problems/validation", "title": _("Invalid request"), "status": 422,
                "detail": "; ".join(problems), "instance": str(request.url.path), "errors": errors}
        if request.headers.get("HX-Request") == "true":
            return HTMLResponse(error_fragment(body), status_code=422)
        if wants_page(request):  # a mistyped address in the browser (/sessions/x/nodes/1001): a page of the app
            return error_page(request, body)
        return JSONResponse(jsonable(body), status_code=422, media_type="application/problem+json")


def jsonable(body: dict[str, object]) -> dict[str, object]:
    from fastapi.encoders import jsonable_encoder

    return jsonable_encoder(body, custom_encoder={ValueError: str, Exception: str})
