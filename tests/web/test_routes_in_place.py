"""The access policy walks included routers in place (issue 33: asking FastAPI for its effective copies of every
route before the first request cost a third of the start's CPU): the same routes, in the same order, with the same
decisions as FastAPI's own view, and a router included with a prefix still matched under it."""

from __future__ import annotations

from fastapi import APIRouter, FastAPI
from fastapi.routing import iter_route_contexts

from drivebench.web import access_policy
from drivebench.web.app import create_app


def _routes(routes: list[object]) -> list[tuple[str, tuple[str, ...]]]:
    return [(str(route.path), tuple(sorted(getattr(route, "methods", None) or ())))  # type: ignore[attr-defined]
            for route in routes if getattr(route, "path", None) is not None]


def test_the_policy_sees_the_routes_fastapi_serves_in_its_order() -> None:
    app = create_app()
    in_place = _routes(list(access_policy.routes_in_place(app.router.routes)))
    assert len(in_place) > 250
    assert in_place == _routes(list(iter_route_contexts(app.router.routes)))
    policies = access_policy.precompute(app)
    assert [(p.template, tuple(sorted(getattr(p.route, "methods", None) or ()))) for p in policies] == in_place


def test_a_router_included_under_a_prefix_is_matched_under_it() -> None:
    inner = APIRouter()

    @inner.post("/things/{thing}")
    def write_thing(thing: int) -> None:
        return None

    app = FastAPI(openapi_url=None, docs_url=None, redoc_url=None)
    app.include_router(inner, prefix="/outer")
    plain = APIRouter()
    plain.include_router(inner)
    app.include_router(plain)
    assert _routes(list(access_policy.routes_in_place(app.router.routes))) == [
        ("/outer/things/{thing}", ("POST",)), ("/things/{thing}", ("POST",))]
    scope = {"type": "http", "method": "POST", "path": "/outer/things/7", "root_path": "", "headers": []}
    decision = access_policy.decide(app, scope)
    assert decision.template == "/outer/things/{thing}"
