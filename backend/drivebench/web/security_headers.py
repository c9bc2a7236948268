"""Browser security headers on every HTTP response: Content-Security-Policy, no framing, no sniffing, no referrer.

The pages load scripts only from /static (no inline script, no inline event handler, no eval: htmx runs with
``allowEval`` off, see base.html), so a stored text that slipped past escaping still cannot run. No page may be
framed by another site (clickjacking a "Start node" button). The JSON API gets the same headers: a response
opened directly in a tab is a page too.

``style-src`` keeps ``'unsafe-inline'``: templates size SVG diagrams and DIP-switch legends with ``style=""``
attributes, and uPlot lays out its plots through style attributes. Styles cannot run script, and every text put
into a page is escaped, so this is the one inline allowance; scripts have none.

FastAPI's /docs and /redoc pages are third-party HTML, served only with ``settings.api_docs`` (development): their
one inline script is allowed by its hash, their assets come from the CDN FastAPI names.
"""

from __future__ import annotations

import base64
import hashlib
import re
from collections.abc import Awaitable, Callable

from starlette.datastructures import MutableHeaders
from starlette.types import Message, Send

PAGE_POLICY = "; ".join([
    "default-src 'self'",
    "script-src 'self'",
    "style-src 'self' 'unsafe-inline'",
    "img-src 'self' data:",  # the favicon is a data: SVG
    "connect-src 'self'",  # fetch and the websockets of this server
    "object-src 'none'",
    "base-uri 'self'",
    "form-action 'self'",
    "frame-ancestors 'none'",
])
DOCS_PATHS = frozenset({"/docs", "/redoc"})
DOCS_CDN = "https://cdn.jsdelivr.net"
INLINE_SCRIPT = re.compile(rb"<script>(.*?)</script>", re.DOTALL)

HEADERS = {
    "X-Frame-Options": "DENY",  # frame-ancestors for browsers without CSP level 2
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "same-origin",  # share-link tokens in page addresses never leave for another site
}


def docs_policy(body: bytes) -> str:
    hashes = " ".join(f"'sha256-{base64.b64encode(hashlib.sha256(script).digest()).decode()}'"
                      for script in INLINE_SCRIPT.findall(body))
    return "; ".join([
        "default-src 'self'",
        f"script-src 'self' {DOCS_CDN} {hashes}",
        f"style-src 'self' 'unsafe-inline' {DOCS_CDN} https://fonts.googleapis.com",
        "font-src 'self' https://fonts.gstatic.com",
        "img-src 'self' data: https://fastapi.tiangolo.com",
        "worker-src 'self' blob:",
        "frame-ancestors 'none'",
    ])


RAW_HEADERS = [(name.lower().encode(), value.encode()) for name, value in
               {"Content-Security-Policy": PAGE_POLICY, **HEADERS}.items()]
"""The headers above as an ASGI response carries them (``web/gate.py`` puts them on every HTTP answer, refusals
too; websockets have no such headers)."""


async def held_docs(answer: Callable[[Send], Awaitable[None]], send: Send, extra: list[tuple[bytes, bytes]]) -> None:
    """The docs page is small: hold it back until its inline script can be hashed into the policy."""
    held: list[Message] = []

    async def hold(message: Message) -> None:
        held.append(message)

    await answer(hold)
    body = b"".join(m.get("body", b"") for m in held if m["type"] == "http.response.body")
    start = next(m for m in held if m["type"] == "http.response.start")
    headers = MutableHeaders(scope=start)
    headers["Content-Security-Policy"] = docs_policy(body)
    headers.update(HEADERS)
    start["headers"] = [*start["headers"], *extra]
    await send(start)
    await send({"type": "http.response.body", "body": body})
