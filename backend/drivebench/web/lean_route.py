"""Routes whose common request skips FastAPI's dependency solving (issue 21, benchmarks/RESULTS.md: Request path).

A parameter read spent about a third of its in-process time in ``solve_dependencies`` and the response model's
second validation: more than the SDO transfer on the event loop. :func:`lean_route` makes an ``APIRoute`` class
whose handler first asks a *lean* function; it answers the request it recognises (plain path parameters, no query)
and returns ``None`` for every other one, which then takes the route's full FastAPI path. The OpenAPI document, the
access gate (a middleware in front of the router) and the problem handlers (exceptions raised in either path) are
the same for both.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Coroutine
from typing import Any

from fastapi import Request, Response
from fastapi.routing import APIRoute

LeanHandler = Callable[[Request], Awaitable[Response | None]]


def lean_route(lean: LeanHandler) -> type[APIRoute]:
    """An ``APIRoute`` class (``route_class_override``) that tries ``lean(request)`` before the full path."""

    class LeanRoute(APIRoute):
        def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
            full = super().get_route_handler()

            async def handler(request: Request) -> Response:
                response = await lean(request)
                return response if response is not None else await full(request)

            return handler

    LeanRoute.__qualname__ = LeanRoute.__name__ = f"LeanRoute[{getattr(lean, '__name__', 'lean')}]"
    return LeanRoute


def path_int(text: str, low: int, high: int) -> int | None:
    """A path parameter as the full path's ``Path(ge=low, le=high)`` reads it when it is plain decimal digits in
    range; None for anything else (the full path then gives its own answer, a 422 with the same words)."""
    if not (text.isascii() and text.isdigit()) or len(text) > 6:
        return None
    number = int(text)
    return number if low <= number <= high else None
