"""Apps of one process share the routes FastAPI builds (issues 29 and 33: building them anew cost every app about
half a second of CPU): a second app's routes are the first app's, already built; a dependency override stays the
one app's; both apps answer through them."""

from __future__ import annotations

from fastapi.routing import iter_route_contexts
from fastapi.testclient import TestClient

from drivebench.errors import NotFound
from drivebench.web import access_policy
from drivebench.web.app import create_app
from drivebench.web.deps import get_state


def _built(app: object) -> list[object]:
    """What FastAPI built for each route of ``app`` to serve it: the analysis of its parameters (``dependant``)."""
    return [getattr(context, "dependant", None) for context in iter_route_contexts(app.router.routes)]  # type: ignore[attr-defined]


def test_a_second_app_serves_the_routes_the_first_built(app_db_url: str) -> None:
    first = create_app()
    access_policy.build_effective_routes(first)
    second = create_app()
    built_first, built_second = _built(first), _built(second)
    assert sum(built is not None for built in built_second) > 250  # the routers' routes (not the app's own)
    assert all(a is b for a, b in zip(built_first, built_second, strict=True) if a is not None)


def test_a_dependency_override_stays_with_its_app(app_db_url: str) -> None:
    async def refusing() -> None:
        raise NotFound("the override of the other app")

    overridden, plain = create_app(), create_app()
    overridden.dependency_overrides[get_state] = refusing
    with TestClient(overridden) as refused, TestClient(plain) as answered:
        assert answered.get("/api/sessions").status_code == 200
        answer = refused.get("/api/sessions")
        assert answer.status_code == 404 and "the override of the other app" in answer.text
        assert answered.get("/api/sessions").status_code == 200
        assert refused.get("/api/interfaces").status_code == 200  # a route without the dependency
