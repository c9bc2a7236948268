"""The sub-path a trusted reverse proxy names per request (``X-Forwarded-Prefix: /drivebench``), as Traefik, Spring
Cloud Gateway and nginx configurations send it: the same as ``serve --root-path`` for requests that come through
that proxy, so one server can be reached at the top and under a proxy's prefix, or under two proxies' prefixes.

Believed only from the proxies ``--forwarded-allow-ips`` names, as ``X-Forwarded-For`` / ``-Proto`` are: the check
runs on the connecting address, before uvicorn's proxy-headers middleware puts the forwarded client address in its
place (so :func:`proxied` wraps both, and ``serve`` hands uvicorn the wrapped app with its own proxy handling off).
"""

from __future__ import annotations

import json
import logging
import re

from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.middleware.proxy_headers import ProxyHeadersMiddleware

from drivebench.i18n import _
from drivebench.web.root import route_path

log = logging.getLogger(__name__)

HEADER = b"x-forwarded-prefix"
_SUB_PATH = re.compile(r"^(/[A-Za-z0-9._~!$&'()*+,;=:@%-]+)+/?$")
"""One or more path segments of URL path characters (RFC 3986 pchar), each after a slash; no empty or dot-only
segment is let through by the check in :func:`sub_path`."""


def sub_path(value: str) -> str | None:
    """The prefix a header value names without its trailing slash ("" for "/"); None when it is no sub-path."""
    if value in ("", "/"):
        return ""
    if not _SUB_PATH.match(value) or any(part in (".", "..") for part in value.strip("/").split("/")):
        return None
    return value.rstrip("/")


class ForwardedPrefix:
    """``X-Forwarded-Prefix`` of a trusted proxy as the request's root path (the ASGI convention uvicorn's
    ``root_path`` follows: the prefix in ``scope["root_path"]`` and in front of ``scope["path"]``), then uvicorn's
    ``X-Forwarded-For`` / ``-Proto`` handling for the same proxies."""

    def __init__(self, app: ASGIApp, trusted: str) -> None:
        self._next = ProxyHeadersMiddleware(app, trusted_hosts=trusted)  # type: ignore[arg-type]
        self._trusted = self._next.trusted_hosts

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            client = scope.get("client")
            named = [value for name, value in scope["headers"] if name == HEADER]
            if named and client and client[0] in self._trusted:
                prefix = sub_path(named[-1].decode("latin-1").strip())
                if prefix is None:
                    await _refuse(scope, send, named[-1].decode("latin-1"))
                    return
                path = route_path(scope)
                scope = {**scope, "root_path": prefix, "path": prefix + path,
                         "raw_path": (prefix + path).encode("latin-1", "replace")}
        await self._next(scope, receive, send)  # type: ignore[arg-type]


async def _refuse(scope: Scope, send: Send, value: str) -> None:
    """A proxy set up wrong: said to its admin in words, nothing served under a prefix nobody meant."""
    detail = _("The reverse proxy sent X-Forwarded-Prefix {value!r}, which is no sub-path (like /drivebench): fix "
               "the proxy's configuration.").format(value=value)
    log.warning("refused X-Forwarded-Prefix %r from %s", value, (scope.get("client") or ("?",))[0])
    if scope["type"] == "websocket":
        await send({"type": "websocket.close", "code": 1008, "reason": detail[:120]})
        return
    body = json.dumps({"type": "/problems/invalid-value", "title": "Bad Request", "status": 400,
                       "detail": detail}).encode()
    await send({"type": "http.response.start", "status": 400,
                "headers": [(b"content-type", b"application/problem+json"),
                            (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


def proxied(app: ASGIApp, trusted: str | None) -> ASGIApp:
    """``app`` with the forwarded headers of the ``trusted`` proxies believed (none: ``app`` as it is)."""
    return ForwardedPrefix(app, trusted) if trusted else app
