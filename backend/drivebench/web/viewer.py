"""The viewer scope of remote-diagnostics share links, enforced for every request that carries a link token.

A token travels as the ``drivebench_viewer`` cookie (set when a share link is opened) or as
``Authorization: Bearer dbv_…`` (scripts). Such a request may only read what DriveBench already holds: the routes
in ``LINK_READS`` (the remote view, network health, emergencies, the bus monitor), which never make a drive answer.
Any other API route is refused with 403 - a parameter, the PDO set-up, a drive's actual values or counters would
be read from the drive over the bus, which a link must never cause - as is any other HTTP method. Other pages lead
to the remote view, and websockets are limited to its read-only stream. A link that shows the scope (``scope`` in
its ``shows``) may also open the Scope page read-only, watch the session's recording over its socket and read the
recording's state and the stored recordings (list, open, export CSV/JSON): all held by the server, no bus traffic;
starting, stopping and deleting stay refused in words. Requests without a token are not affected.
"""

from __future__ import annotations

from http.cookies import SimpleCookie

import anyio.to_thread
from fastapi import Request
from starlette.datastructures import Headers
from starlette.responses import JSONResponse, RedirectResponse
from starlette.types import Receive, Scope, Send

from drivebench.errors import AccessDenied, DriveBenchError
from drivebench.i18n import N_, _
from drivebench.services.users.sharing import TOKEN_PREFIX, ShareLink, ShareLinks
from drivebench.web import access_policy
from drivebench.web.problems import problem_body
from drivebench.web.root import route_path, under_root

COOKIE = "drivebench_viewer"
SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}
VIEWER_WEBSOCKETS = ("/ws/remote",)
_S = "/api/sessions/{session_id}"
LINK_READS = frozenset({
    "/remote", "/remote/{token}", "/api/remote/{token}/content", "/static", "/openapi.json",
    "/api/health", "/api/health/nodes", "/api/auth/me", "/api/sessions", _S, _S + "/nodes", _S + "/nodes/{node_id}",
    _S + "/nodes/{node_id}/emcy", _S + "/diagnostics/report",
    _S + "/monitor", _S + "/monitor/history", _S + "/monitor/trace",
})
"""The route templates (GET) a link may read: each answers from the consumers' and the monitor's cached state."""
SCOPE_READS = frozenset({
    "/scope/{session_id}", _S + "/scope/run", "/api/scope/recordings", "/api/scope/recordings/{recording_id}",
    "/api/scope/recordings/{recording_id}/export", "/ws/sessions/{session_id}/scope",
})
"""What a link that shows the scope may also read: the run's state and samples as the server holds them, and what
is stored."""
SCOPE_WRITES = frozenset({_S + "/scope/run", _S + "/scope/run/stop", "/api/scope/recordings/{recording_id}"})


def token_of(headers: Headers) -> str | None:
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer ") and auth[7:].strip().startswith(TOKEN_PREFIX):
        return auth[7:].strip()
    cookies = headers.get("cookie", "")
    if COOKIE not in cookies:  # the common case: no link cookie, nothing to parse
        return None
    cookie = SimpleCookie()
    try:
        cookie.load(cookies)
    except Exception:  # a malformed cookie header is ignored, as browsers do
        return None
    morsel = cookie.get(COOKIE)
    return morsel.value if morsel and morsel.value.startswith(TOKEN_PREFIX) else None


async def link_admitted(scope: Scope, receive: Receive, send: Send, links: ShareLinks, headers: Headers,
                        decision: access_policy.Decision) -> bool:
    """A request carrying a link token: the link checked and marked in ``scope["state"]``, what it may not do
    refused, the engineer's pages led to the remote view. False: answered here (``web/gate.py`` stops)."""
    if (token := token_of(headers)) is None:
        return True
    try:
        link = await anyio.to_thread.run_sync(links.check, token)
        readable = _allow(scope, decision, link)
    except DriveBenchError as exc:
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4403, "reason": exc.detail[:120]})
            return False
        body = problem_body(exc, scope.get("path", ""))
        response = JSONResponse(body, status_code=int(body["status"]),  # type: ignore[call-overload]
                                media_type="application/problem+json")
        await response(scope, receive, send)
        return False
    state = scope.setdefault("state", {})
    state["viewer"], state["viewer_token"] = link, token
    if not readable:
        # The engineer's screens are not for link holders: they land on the remote view.
        await RedirectResponse(under_root(scope, f"/remote/{token}"), status_code=303)(scope, receive, send)
        return False
    return True


def _allow(scope: Scope, decision: access_policy.Decision, link: ShareLink) -> bool:
    """Raise for what a link may not do; False for a page it is led away from to the remote view."""
    path = route_path(scope)
    shows_scope = "scope" in link.shows and decision.template in SCOPE_READS
    if scope["type"] == "websocket":
        if not path.startswith(VIEWER_WEBSOCKETS) and not shows_scope:
            raise AccessDenied(_("A remote diagnostics link may only watch the remote diagnostics stream."))
        return True
    if scope.get("method", "GET") not in SAFE_METHODS:
        if decision.template in SCOPE_WRITES:
            raise AccessDenied(_("A remote diagnostics link is read-only: it can watch a scope recording and open or "
                                 "export stored ones; it cannot start, stop or delete a recording."),
                               hint=N_("Ask the engineer on site to start or stop the recording."))
        raise AccessDenied(_("A remote diagnostics link is read-only: it cannot write parameters, send NMT "
                             "commands or PDOs, or change anything on this server."),
                           hint=N_("Ask the engineer on site to make the change."))
    if decision.template in LINK_READS or shows_scope:
        return True
    if path.startswith("/api/"):
        raise AccessDenied(
            _("A remote diagnostics link shows only what DriveBench already holds (network health, emergencies, "
              "the bus monitor) and never makes a drive answer over the bus: {path} is not open to it.").format(
                path=path),
            hint=N_("Ask the engineer on site to read it for you."))
    return False


def viewer_of(request: Request) -> ShareLink | None:
    """The share link the request came through, or None for a local engineer."""
    link: ShareLink | None = getattr(request.state, "viewer", None)
    return link


def viewer_token(request: Request) -> str | None:
    """The token of the share link the request came through (it is not stored on the server)."""
    token: str | None = getattr(request.state, "viewer_token", None)
    return token


def require_engineer(request: Request) -> None:
    """For actions a link holder must not take even where the role table would let a viewer."""
    if viewer_of(request) is not None:
        raise AccessDenied(_("Not available through a remote diagnostics link."))
