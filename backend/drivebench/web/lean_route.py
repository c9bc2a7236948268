"""Routes whose common request is answered by the gate, before the router (issue 21, benchmarks/RESULTS.md: Request
path).

A parameter read spent about a third of its in-process time in ``solve_dependencies`` and the response model's
second validation, more than the SDO transfer on the event loop; and the router's own layers (exception and exit-stack
middleware, matching the path a second time, the endpoint wrappers) cost about as much again. :func:`lean_route`
makes an ``APIRoute`` class that carries a *lean* function: the gate (``web/gate.py``), once the request is
admitted, calls it with the path's parameters (matched once, remembered with the access decision); it answers the
request it recognises (plain path parameters, no query) and returns ``None`` for every other one, which then goes on
through the router to the route's full FastAPI path. The OpenAPI document, the access gate and the problem handlers
(an exception the lean function raises is answered by the app's handler for it) are the same for both.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import Request, Response
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException
from starlette.types import Receive, Scope, Send

from drivebench.web.deferred_route import DeferredRoute

LeanHandler = Callable[[Request], Awaitable[Response | None]]


def lean_route(lean: LeanHandler) -> type[APIRoute]:
    """An ``APIRoute`` class (``route_class_override``) whose GET requests the gate first offers to ``lean``."""

    class LeanRoute(DeferredRoute):
        pass

    LeanRoute.lean = staticmethod(lean)  # type: ignore[attr-defined]
    LeanRoute.__qualname__ = LeanRoute.__name__ = f"LeanRoute[{getattr(lean, '__name__', 'lean')}]"
    return LeanRoute


async def answered(lean: LeanHandler, path_params: dict[str, Any], scope: Scope, receive: Receive,
                   send: Send) -> bool:
    """Whether ``lean`` answered the request (sent its response, or the app's problem for what it raised)."""
    scope["path_params"] = path_params
    request = Request(scope, receive)
    try:
        response = await lean(request)
    except Exception as exc:
        handler = _handler_for(scope["app"], exc)
        if handler is None:
            raise
        response = await handler(request, exc)
    if response is None:
        return False
    await response(scope, receive, send)
    return True


def _handler_for(app: Any, exc: Exception) -> Callable[[Request, Exception], Awaitable[Response]] | None:
    """The app's exception handler for ``exc``, chosen as Starlette's exception middleware chooses it."""
    handlers = app.exception_handlers
    if isinstance(exc, HTTPException) and exc.status_code in handlers:
        return handlers[exc.status_code]
    for kind in type(exc).__mro__:
        if kind in handlers and kind is not Exception:  # Exception's handler is the server-error middleware's
            return handlers[kind]
    return None


def path_int(text: str, low: int, high: int) -> int | None:
    """A path parameter as the full path's ``Path(ge=low, le=high)`` reads it when it is plain decimal digits in
    range; None for anything else (the full path then gives its own answer, a 422 with the same words)."""
    if not (text.isascii() and text.isdigit()) or len(text) > 6:
        return None
    number = int(text)
    return number if low <= number <= high else None
