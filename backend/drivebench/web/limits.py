"""Request bodies past the upload limit are refused with 413 before the server reads them.

A declared ``Content-Length`` over the limit is answered at once, without reading a byte of the body; a body
without one (chunked) is counted as it arrives and cut as soon as it passes the limit. Either way the client gets
problem+json (htmx: an error fragment) in words: "The file is 7.4 MB; uploads are limited to 5 MB."
The batch upload (many files or a zip at once, ``BATCH_PATHS``) has its own, larger limit.
Once the 413 is sent the route sees a disconnected client, and whatever it answers or raises is dropped.
"""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivebench import i18n
from drivebench.errors import ContentTooLarge
from drivebench.i18n import _
from drivebench.web.problems import error_fragment, problem_body
from drivebench.web.root import route_path

MULTIPART_OVERHEAD_BYTES = 64 * 1024
"""Room for the multipart boundary and part headers around a file of exactly the limit."""
BATCH_PATHS = frozenset({"/api/profiles/batch", "/ui/profiles/batch"})
"""Routes that take many files at once: limited to ``batch_bytes``, not to the one-file limit."""


def megabytes(count: int) -> str:
    """``7759462`` -> ``7.4 MB``, ``5242880`` -> ``5 MB`` (MB of 1024 x 1024 bytes, as file managers show)."""
    return f"{i18n.number(round(count / 2**20, 1))} MB"  # 7,4 MB in German


class BodyLimit:
    """Refuse HTTP request bodies over ``limit_bytes`` (plus multipart framing) with 413 (``web/gate.py`` runs it)."""

    def __init__(self, limit_bytes: int, batch_bytes: int | None = None) -> None:
        self.limit_bytes = limit_bytes
        self.batch_bytes = max(batch_bytes or limit_bytes, limit_bytes)

    def limit_for(self, path: str) -> int:
        """The body limit of a request to ``path`` (without the multipart framing)."""
        return self.batch_bytes if path in BATCH_PATHS else self.limit_bytes

    async def run(self, scope: Scope, receive: Receive, send: Send, headers: Headers, app: ASGIApp) -> None:
        """``app`` with the request's body limited."""
        declared = headers.get("content-length")
        if declared is None and "transfer-encoding" not in headers:
            await app(scope, receive, send)  # no body (HTTP/1.1 has none without either header): nothing to count
            return
        limit = self.limit_for(route_path(scope))
        cap = limit + MULTIPART_OVERHEAD_BYTES
        if declared is not None and declared.isdigit() and int(declared) > cap:
            await self.refusal(headers, scope, limit, int(declared))(scope, receive, send)
            return
        received = 0
        refused = False
        started = False

        async def limited_receive() -> Message:
            nonlocal received, refused
            if refused:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > cap:
                    refused = True
                    if not started:
                        await self.refusal(headers, scope, limit, None)(scope, receive, send)
                    return {"type": "http.disconnect"}
            return message

        async def guarded_send(message: Message) -> None:
            nonlocal started
            if refused:
                return  # the 413 is the answer
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await app(scope, limited_receive, guarded_send)
        except Exception:
            if not refused:
                raise
            # The route failed on the body it did not get; the client already has its 413.

    @staticmethod
    def refusal(headers: Headers, scope: Scope, limit_bytes: int, declared: int | None) -> Response:
        is_file = headers.get("content-type", "").startswith("multipart/form-data")
        limit = megabytes(limit_bytes)
        if declared is not None:
            detail = (_("The file is {size}; uploads are limited to {limit}.") if is_file
                      else _("The request body is {size}; uploads are limited to {limit}.")).format(
                size=megabytes(declared), limit=limit)
        else:
            detail = (_("The file is larger than {limit}; uploads are limited to {limit}.") if is_file
                      else _("The request body is larger than {limit}; uploads are limited to {limit}.")).format(
                limit=limit)
        body = problem_body(ContentTooLarge(detail), scope.get("path", ""))
        if headers.get("hx-request") == "true":
            return HTMLResponse(error_fragment(body), status_code=413, headers={"Connection": "close"})
        return JSONResponse(body, status_code=413, media_type="application/problem+json",
                            headers={"Connection": "close"})
