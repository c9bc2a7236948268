"""The app's routes, built once per process and shared by every app it creates (issues 29 and 33).

FastAPI builds an included router's effective routes (each parameter's pydantic field, the response model, the
endpoint's handler) once per inclusion: an app that includes the routers anew built all ~290 again, about half a
second of CPU per app on a quiet 2-core machine, paid by every test that starts one. Here the routers are included
once into a template router and each app takes the template's included routers: the first app's build serves them
all. FastAPI builds them on first use, so the first app of a process builds them as before
(``access_policy.build_effective_routes``); every later one finds them built.

What FastAPI ties to the including app is ``app.dependency_overrides``: the shared routes ask the app that serves the
request (:class:`ServingApp` names it), so an override stays the one app's.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from contextvars import ContextVar
from typing import Any

from fastapi import APIRouter, FastAPI
from starlette.routing import BaseRoute
from starlette.types import ASGIApp, Receive, Scope, Send

_serving: ContextVar[Any] = ContextVar("drivebench_serving_app", default=None)


class _ServingAppOverrides:
    """FastAPI's ``dependency_overrides_provider`` of the shared routes: the overrides of the app serving the
    request (none outside a request)."""

    @property
    def dependency_overrides(self) -> Mapping[Any, Any]:
        app = _serving.get()
        return getattr(app, "dependency_overrides", None) or {}


class ServingApp:
    """ASGI middleware: names the app serving a request or websocket for the shared routes' dependency overrides."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        token = _serving.set(scope.get("app"))
        try:
            await self.app(scope, receive, send)
        finally:
            _serving.reset(token)


_templates: dict[tuple[int, ...], tuple[BaseRoute, ...]] = {}
"""The included routers per sequence of routers (by identity: the module-level routers live as long as the
process)."""
_templates_lock = threading.Lock()


def _template(routers: Sequence[APIRouter]) -> tuple[BaseRoute, ...]:
    key = tuple(id(router) for router in routers)
    with _templates_lock:
        routes = _templates.get(key)
        if routes is None:
            template = APIRouter(dependency_overrides_provider=_ServingAppOverrides())
            for router in routers:
                if router.on_startup or router.on_shutdown:
                    raise ValueError(f"router {router.prefix or '/'} has start-up or shut-down handlers: "
                                     "include it per app")
                template.include_router(router)
            routes = _templates[key] = tuple(template.routes)
        return routes


def include(app: FastAPI, routers: Sequence[APIRouter]) -> None:
    """Include ``routers`` in ``app`` in this order, as ``app.include_router`` each would, with the routes this
    process built for the first app that included the same routers."""
    app.router.routes.extend(_template(routers))
    app.add_middleware(ServingApp)
