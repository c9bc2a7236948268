"""The language of each request and websocket, and the header's switch (en | de).

The gate (``web/gate.py``) picks the language once (``i18n.negotiate``: the switch's cookie, else
``Accept-Language``) and holds it for all the request renders or raises, refusals too; every HTTP answer says it
varies with both headers, so no cache hands a German page to an English browser.
"""

from __future__ import annotations

from functools import lru_cache

from fastapi import APIRouter, Request
from starlette.datastructures import Headers
from starlette.responses import RedirectResponse

from drivebench import i18n
from drivebench.errors import NotFound
from drivebench.web import cookies
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.root import cookie_path, under_root

router = APIRouter(route_class=DeferredRoute)
COOKIE_MAX_AGE_S = 365 * 24 * 3600
VARY = ("Accept-Language", "Cookie")
VARY_BYTES = tuple(name.encode() for name in VARY)
_VARY = b", ".join(VARY_BYTES)


def of_request(headers: Headers) -> str:
    """The language of a request or websocket (``web/gate.py`` asks once per request): the switch's cookie, else
    ``Accept-Language``."""
    accept = headers.get("accept-language")
    chosen = cookies.value(headers.get("cookie"), i18n.COOKIE)
    chosen = chosen if chosen in i18n.LOCALES else None
    if accept is not None and len(accept) > ACCEPT_REMEMBERED_CHARS:
        return i18n.negotiate(accept, chosen)
    return _negotiated(accept, chosen)


ACCEPT_REMEMBERED_CHARS = 200
"""A browser sends the same Accept-Language with every request: the answers for short ones are remembered."""


@lru_cache(maxsize=256)
def _negotiated(accept_language: str | None, cookie: str | None) -> str:
    return i18n.negotiate(accept_language, cookie)


def varying(headers: list[tuple[bytes, bytes]], locale: str) -> list[tuple[bytes, bytes]]:
    """A response's raw headers, saying it varies with the language's two headers and which language it speaks
    (a route's own ``Vary`` names are kept, its ``Content-Language`` wins)."""
    vary_at = language_given = None
    for position, (name, _value) in enumerate(headers):
        lowered = name.lower()
        if lowered == b"vary":
            vary_at = position
        elif lowered == b"content-language":
            language_given = position
    if vary_at is None:
        headers.append((b"vary", _VARY))
    else:
        value = headers[vary_at][1]
        present = {token.strip().lower() for token in value.split(b",")}
        missing = [name for name in VARY_BYTES if name.lower() not in present]
        if missing:
            headers[vary_at] = (b"vary", b", ".join([value, *missing]))
    if language_given is None:
        headers.append((b"content-language", locale.encode()))
    return headers


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
    response = RedirectResponse(under_root(request.scope, _local_target(next)), status_code=303)
    response.set_cookie(i18n.COOKIE, code, max_age=COOKIE_MAX_AGE_S, path=cookie_path(request.scope), samesite="lax",
                        secure=request.url.scheme == "https")
    return response
