"""Every request and websocket passes one gate, in one pass: a pure ASGI middleware (no BaseHTTPMiddleware).

In this order, as the separate middlewares did before (issue 21: one pass instead of five layers, the headers read
once, the route's policy looked up once, precomputed at start-up by ``access_policy.precompute``):

1. HTTP answers get the browser security headers (``security_headers``; HSTS over https when switched on), refusals
   too; the docs pages are held back until their inline script is hashed into the policy.
2. A request body past the upload limit is refused with 413 (``limits``).
3. A share-link token (``viewer``): the link checked, what a link may not do refused, pages led to the remote view.
4. Host and Origin, sign-in, role and CSRF (``access``); the audit log's ``current_user`` is who signed in.
"""

from __future__ import annotations

from functools import partial

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

from drivebench.services.users import audit
from drivebench.services.users.sharing import ShareLinks
from drivebench.web import access, access_policy, security_headers, viewer
from drivebench.web.limits import BodyLimit
from drivebench.web.tls import HSTS_HEADER


class RequestGate:
    def __init__(self, app: ASGIApp, *, links: ShareLinks, limit_bytes: int, hsts: bool = False) -> None:
        self.app = app
        self.links = links
        self.body_limit = BodyLimit(limit_bytes)
        self.hsts = hsts

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind == "websocket":
            await self._admitted(scope, receive, send, Headers(scope=scope))
        elif kind == "http":
            extra = [HSTS_HEADER] if self.hsts and scope.get("scheme") == "https" else []
            if scope["path"] in security_headers.DOCS_PATHS:
                await security_headers.held_docs(partial(self._http, scope, receive), send, extra)
            else:
                await self._http(scope, receive, security_headers.adding_headers(send, extra))
        else:
            await self.app(scope, receive, send)

    async def _http(self, scope: Scope, receive: Receive, send: Send) -> None:
        headers = Headers(scope=scope)
        await self.body_limit.run(scope, receive, send, headers,
                                  lambda scope, receive, send: self._admitted(scope, receive, send, headers))

    async def _admitted(self, scope: Scope, receive: Receive, send: Send, headers: Headers) -> None:
        decision = access_policy.decide(scope["app"], scope)
        if not await viewer.link_admitted(scope, receive, send, self.links, headers, decision):
            return
        admitted = await access.admitted(scope, receive, send, headers, decision)
        if admitted is None:
            return
        receive, user = admitted
        if user is None:
            await self.app(scope, receive, send)
            return
        token = audit.current_user.set(user)
        try:
            await self.app(scope, receive, send)
        finally:
            audit.current_user.reset(token)
