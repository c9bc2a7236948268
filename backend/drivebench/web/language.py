"""The language of each request and websocket, and the header's switch (en | de).

The middleware picks the language once (``i18n.negotiate``: the switch's cookie, else ``Accept-Language``) and
holds it for all the request renders or raises; every HTTP answer says it varies with both headers, so no cache
hands a German page to an English browser.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from starlette.datastructures import MutableHeaders
from starlette.requests import HTTPConnection
from starlette.responses import RedirectResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivebench import i18n
from drivebench.errors import NotFound

router = APIRouter()
COOKIE_MAX_AGE_S = 365 * 24 * 3600
VARY = ("Accept-Language", "Cookie")


class LanguageMiddleware:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket"):
            connection = HTTPConnection(scope)
            locale = i18n.negotiate(connection.headers.get("accept-language"), connection.cookies.get(i18n.COOKIE))
            await self._speaking(locale, scope, receive, send)
        else:
            await self.app(scope, receive, send)

    async def _speaking(self, locale: str, scope: Scope, receive: Receive, send: Send) -> None:
        async def send_varying(message: Message) -> None:
            if message["type"] == "http.response.start":
                answer = MutableHeaders(scope=message)
                present = {v.strip().lower() for v in answer.get("vary", "").split(",") if v.strip()}
                for name in VARY:
                    if name.lower() not in present:
                        answer.add_vary_header(name)
                answer.setdefault("content-language", locale)
            await send(message)

        with i18n.using(locale):
            await self.app(scope, receive, send_varying if scope["type"] == "http" else send)


def _local_target(target: str | None) -> str:
    """Back to the page the switch was pressed on; only a path of this server (no open redirect)."""
    if not target or not target.startswith("/") or target.startswith("//") or "\\" in target:
        return "/"
    return target


@router.get("/language/{code}", include_in_schema=False)
async def switch_language(code: str, request: Request, next: str | None = None) -> RedirectResponse:
    if code not in i18n.LOCALES:
        raise NotFound(i18n._("There is no language {code}: choose one of {choices}.").format(
            code=code, choices=", ".join(i18n.LOCALES)))
    response = RedirectResponse(_local_target(next), status_code=303)
    response.set_cookie(i18n.COOKIE, code, max_age=COOKIE_MAX_AGE_S, path="/", samesite="lax",
                        secure=request.url.scheme == "https")
    return response
