"""Every request and websocket passes one gate, in one pass: a pure ASGI middleware (no BaseHTTPMiddleware).

In this order, as the separate middlewares did before (issue 21: one pass instead of six layers, the headers read
once, the route's policy looked up once, precomputed at start-up by ``access_policy.precompute``):

1. The language (``language``): picked once, held for everything inside, refusals too; every HTTP answer says it
   varies with the language's headers and which language it speaks.
2. HTTP answers get the browser security headers (``security_headers``; HSTS over https when switched on), refusals
   too; the docs pages are held back until their inline script is hashed into the policy.
3. A request body past the upload limit (the batch upload's own) is refused with 413 (``limits``).
4. A share-link token (``viewer``): the link checked, what a link may not do refused, pages led to the remote view.
5. Host and Origin, sign-in, role and CSRF (``access``); the audit log's user (``safety.audit_user``) is who signed
   in. A websocket is re-checked every second while it is open (``live_access``).
6. A route with a lean answer (``lean_route``) answers its common request here, without the router's second match
   and FastAPI's dependency solving; every other request goes on to the app.
"""

from __future__ import annotations

import logging
from functools import partial

from sqlalchemy.exc import InterfaceError, OperationalError
from starlette.datastructures import Headers
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivebench import i18n
from drivebench.i18n import _
from drivebench.services.storage import reachability
from drivebench.services.users.sharing import ShareLinks
from drivebench.web import (
    access,
    access_policy,
    language,
    lean_route,
    live_access,
    problems,
    safety,
    security_headers,
    viewer,
)
from drivebench.web.limits import BodyLimit
from drivebench.web.root import route_path
from drivebench.web.tls import HSTS_HEADER

log = logging.getLogger(__name__)


class RequestGate:
    def __init__(self, app: ASGIApp, *, links: ShareLinks, sign_ins: access.SignIns, limit_bytes: int,
                 batch_bytes: int | None = None, hsts: bool = False) -> None:
        self.app = app
        self.links = links
        self.sign_ins = sign_ins
        self.body_limit = BodyLimit(limit_bytes, batch_bytes)
        self.hsts = hsts
        self._added = {scheme: _Added(security_headers.RAW_HEADERS + ([HSTS_HEADER] if hsts and scheme == "https"
                                                                     else []))
                       for scheme in ("http", "https")}
        """The headers every answer gets, and their names, per scheme (HSTS only over https), made once."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        locale = language.of_request(headers)
        with i18n.using(locale):
            if kind == "websocket":
                await self._admitted(scope, receive, send, headers)
                return
            https = scope.get("scheme") == "https"
            added = _answering(send, self._added["https" if https else "http"], locale)
            answer = _Tracked(added)
            try:
                if route_path(scope) in security_headers.DOCS_PATHS:  # rare: worked out per request
                    extra = [HSTS_HEADER] if self.hsts and https else []
                    answer = _Tracked(_answering(send, _NOTHING_ADDED, locale))
                    await security_headers.held_docs(partial(self._http, scope, receive, headers), answer, extra)
                else:
                    await self._http(scope, receive, headers, answer)
            except (OperationalError, InterfaceError) as exc:  # the database went away: 503 in words
                if answer.started:
                    raise
                await _database_unavailable(scope, added, exc)
            except Exception:
                if not answer.started:  # a bug: a problem with the headers; the server logs the error as before
                    await _server_error(scope, added)
                raise

    async def _http(self, scope: Scope, receive: Receive, headers: Headers, send: Send) -> None:
        await self.body_limit.run(scope, receive, send, headers,
                                  lambda scope, receive, send: self._admitted(scope, receive, send, headers))

    async def _admitted(self, scope: Scope, receive: Receive, send: Send, headers: Headers) -> None:
        decision = access_policy.decide(scope["app"], scope)
        scope.setdefault("state", {})["route_template"] = decision.template  # metrics count by it (web/metrics.py)
        if not await viewer.link_admitted(scope, receive, send, self.links, headers, decision):
            return
        admitted = await access.admitted(scope, receive, send, headers, decision, self.sign_ins)
        if admitted is None:
            return
        receive, user = admitted
        if user is not None:  # the audit log names who signed in (web/safety.audit_user)
            scope.setdefault("state", {})[safety.AUDIT_USER] = user
        if scope["type"] == "websocket":  # open as long as its user may: re-checked every second
            await live_access.serve(self.app, scope, receive, send, partial(
                access.still_admitted, scope, headers, decision, self.links, self.sign_ins))
            return
        if decision.lean is not None and scope.get("method") == "GET" and await lean_route.answered(
                decision.lean, decision.path_params, scope, receive, send):
            return
        await self.app(scope, receive, send)


class _Tracked:
    """``send`` that remembers whether the answer has started."""

    def __init__(self, send: Send) -> None:
        self.send = send
        self.started = False

    async def __call__(self, message: Message) -> None:
        self.started = self.started or message["type"] == "http.response.start"
        await self.send(message)


async def _server_error(scope: Scope, send: Send) -> None:
    """The 500 of an unexpected error: a problem in words, nothing of the error itself (the log has that)."""
    body = {"type": "about:blank", "title": _("Internal server error"), "status": 500,
            "detail": _("The server failed on this request; its log has the details."), "instance": scope["path"]}
    await JSONResponse(body, status_code=500, media_type="application/problem+json")(scope, _nothing, send)


async def _database_unavailable(scope: Scope, send: Send, exc: Exception) -> None:
    problem = reachability.unavailable(exc)
    log.warning("%s %s: %s", scope.get("method", "WEBSOCKET"), scope["path"], problem.detail)
    body = problems.problem_body(problem, scope["path"])
    await JSONResponse(body, status_code=503, media_type="application/problem+json")(scope, _nothing, send)


async def _nothing() -> Message:
    return {"type": "http.disconnect"}


class _Added:
    def __init__(self, headers: list[tuple[bytes, bytes]]) -> None:
        self.headers = headers
        self.names = frozenset(name for name, _value in headers)


_NOTHING_ADDED = _Added([])


def _answering(send: Send, added: _Added, locale: str) -> Send:
    """``send`` that puts the gate's headers on the answer's start: the language's, then ``added`` (these replace
    a route's own of the same name)."""
    headers, names = added.headers, added.names

    async def send_with_headers(message: Message) -> None:
        if message["type"] == "http.response.start":
            kept = [(name, value) for name, value in message.get("headers", ()) if name.lower() not in names]
            message["headers"] = language.varying(kept, locale) + headers
        await send(message)

    return send_with_headers
