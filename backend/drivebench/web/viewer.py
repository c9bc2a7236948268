"""The viewer scope of remote-diagnostics share links, enforced for every request that carries a link token.

A token travels as the ``drivebench_viewer`` cookie (set when a share link is opened) or as
``Authorization: Bearer dbv_…`` (scripts). Such a request may only read: any other HTTP method is refused with
403, and websockets are limited to the read-only remote stream. Requests without a token are not affected here.
"""

from __future__ import annotations

from http.cookies import SimpleCookie

from fastapi import Request
from starlette.responses import JSONResponse, RedirectResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from drivebench.errors import AccessDenied, DriveBenchError
from drivebench.services.sharing import TOKEN_PREFIX, ShareLink, ShareLinks
from drivebench.web.problems import problem_body

COOKIE = "drivebench_viewer"
SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}
VIEWER_WEBSOCKETS = ("/ws/remote",)
VIEWER_PATHS = ("/remote", "/api/", "/static/", "/openapi.json", "/docs")


def token_of(scope: Scope) -> str | None:
    headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer ") and auth[7:].strip().startswith(TOKEN_PREFIX):
        return auth[7:].strip()
    cookie = SimpleCookie()
    try:
        cookie.load(headers.get("cookie", ""))
    except Exception:  # a malformed cookie header is ignored, as browsers do
        return None
    morsel = cookie.get(COOKIE)
    return morsel.value if morsel and morsel.value.startswith(TOKEN_PREFIX) else None


class ViewerScope:
    def __init__(self, app: ASGIApp, links: ShareLinks) -> None:
        self.app = app
        self.links = links

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket") or (token := token_of(scope)) is None:
            await self.app(scope, receive, send)
            return
        try:
            link = self.links.check(token)
            self._allow(scope)
        except DriveBenchError as exc:
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 4403, "reason": exc.detail[:120]})
                return
            body = problem_body(exc, scope.get("path", ""))
            response = JSONResponse(body, status_code=int(body["status"]),  # type: ignore[call-overload]
                                    media_type="application/problem+json")
            await response(scope, receive, send)
            return
        scope.setdefault("state", {})["viewer"] = link
        path = scope.get("path", "")
        if scope["type"] == "http" and not path.startswith(VIEWER_PATHS):
            # The engineer's screens are not for link holders: they land on the remote view.
            await RedirectResponse(f"/remote/{link.token}", status_code=303)(scope, receive, send)
            return
        await self.app(scope, receive, send)

    @staticmethod
    def _allow(scope: Scope) -> None:
        path = scope.get("path", "")
        if scope["type"] == "websocket":
            if not path.startswith(VIEWER_WEBSOCKETS):
                raise AccessDenied("A remote diagnostics link may only watch the remote diagnostics stream.")
            return
        if scope.get("method", "GET") not in SAFE_METHODS:
            raise AccessDenied("A remote diagnostics link is read-only: it cannot write parameters, send NMT "
                               "commands or PDOs, or change anything on this server.",
                               hint="Ask the engineer on site to make the change.")


def viewer_of(request: Request) -> ShareLink | None:
    """The share link the request came through, or None for a local engineer."""
    link: ShareLink | None = getattr(request.state, "viewer", None)
    return link


def require_engineer(request: Request) -> None:
    """For read endpoints a viewer still must not see (e.g. the list of share links)."""
    if viewer_of(request) is not None:
        raise AccessDenied("Not available through a remote diagnostics link.")

