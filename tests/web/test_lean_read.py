"""The lean parameter read (issue 21: ``GET …/parameters/{ref}`` without FastAPI's dependency solving) answers
exactly as the full path does: the same body, the same problems, the same 422s, behind the same gate. A real
`drivebench hub` and `drivebench simulate` in processes of their own, the server in uvicorn, real HTTP."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest

from drivebench import __version__
from drivebench.errors import NotFound
from drivebench.web.app import create_app
from drivebench.web.deps import get_session, get_state
from tests.conftest import serve_app
from tests.transport.test_multiprocess import hub_and_simulator  # noqa: F401  (the fixture)
from tests.web.test_access import own_db, users  # noqa: F401  (the fixtures)

pytestmark = pytest.mark.slow  # a hub and a simulator process started for each test: `make test-quick` leaves it out

NODE = 5
PROFILE = "lenze-8400-motec-canopen"


@pytest.fixture
def served(hub_and_simulator: str) -> Iterator[tuple[httpx.Client, Any, str]]:  # noqa: F811
    """The server on the hub's bus with node 5 added; (client, app, the node's API path)."""
    app = create_app(buses=[hub_and_simulator])
    with serve_app(app) as url, httpx.Client(base_url=url, timeout=30) as http:
        session = http.get("/api/sessions").json()[0]["id"]
        http.post(f"/api/sessions/{session}/nodes", json={"node_id": NODE, "profile_id": PROFILE}).raise_for_status()
        yield http, app, f"/api/sessions/{session}/nodes/{NODE}"


@contextlib.contextmanager
def full_path_refused(app: Any, dependency: Callable[..., Any]) -> Iterator[None]:
    """While inside, the route's dependency ``dependency`` refuses: only the full path solves it."""

    async def refusing() -> None:
        raise NotFound("the full path ran")

    app.dependency_overrides[dependency] = refusing
    try:
        yield
    finally:
        app.dependency_overrides.clear()


def _without_time(body: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in body.items() if key != "read_at"}


def test_the_lean_read_answers_as_the_full_path(served: tuple[httpx.Client, Any, str]) -> None:
    http, _, base = served
    for ref in ("0x1017.0", "C00099", "C00061"):  # expedited, segmented (the firmware string), a vendor code
        lean = http.get(f"{base}/parameters/{ref}")
        full = http.get(f"{base}/parameters/{ref}", params={"transfer": "auto"})
        assert lean.status_code == full.status_code == 200, (lean.text, full.text)
        assert lean.headers["content-type"] == full.headers["content-type"] == "application/json"
        assert _without_time(lean.json()) == _without_time(full.json())
        assert lean.headers["x-content-type-options"] == "nosniff"  # the gate's headers: it ran in front
    assert http.get(f"{base}/parameters/C00061").json()["raw"] == 43  # 8400 motec manual 9.3


@pytest.mark.parametrize("where", ["unknown session", "unknown node", "unknown ref", "abort"])
def test_the_lean_read_gives_the_full_paths_problems(served: tuple[httpx.Client, Any, str], where: str) -> None:
    http, _, base = served
    path = {"unknown session": base.replace("/sessions/", "/sessions/nope-") + "/parameters/0x1017.0",
            "unknown node": base.removesuffix(f"/{NODE}") + "/99/parameters/0x1017.0",
            "unknown ref": f"{base}/parameters/C99999",
            "abort": f"{base}/parameters/0x1017.7"}[where]
    lean = http.get(path)
    full = http.get(path, params={"transfer": "auto"})
    assert lean.status_code == full.status_code and lean.status_code >= 400, (lean.text, full.text)
    assert lean.headers["content-type"] == full.headers["content-type"] == "application/problem+json"
    assert lean.json() == full.json()


@pytest.mark.parametrize("node", ["0", "128", "five", "1e2", "٥"])
def test_a_node_id_the_lean_read_does_not_take_gets_the_full_paths_422(served: tuple[httpx.Client, Any, str],
                                                                       node: str) -> None:
    http, _, base = served
    answer = http.get(base.removesuffix(f"/{NODE}") + f"/{node}/parameters/0x1017.0")
    assert answer.status_code == 422
    assert answer.headers["content-type"] == "application/problem+json"
    assert "node_id" in answer.text


def test_the_lean_read_is_the_one_taken(served: tuple[httpx.Client, Any, str]) -> None:
    """A plain read does not solve the route's dependencies; a read with a query does (the full path)."""
    http, app, base = served
    with full_path_refused(app, get_session):
        assert http.get(f"{base}/parameters/0x1017.0").status_code == 200
        full = http.get(f"{base}/parameters/0x1017.0", params={"transfer": "auto"})
        assert full.status_code == 404 and "the full path ran" in full.text


@contextlib.contextmanager
def router_calls(app: Any) -> Iterator[list[str]]:
    """The paths of the requests that reach the app's router while inside."""
    entered: list[str] = []
    inner = app.router.middleware_stack

    async def counting(scope: Any, receive: Any, send: Any) -> None:
        entered.append(scope["path"])
        await inner(scope, receive, send)

    app.router.middleware_stack = counting
    try:
        yield entered
    finally:
        app.router.middleware_stack = inner


def test_the_gate_answers_the_lean_read_before_the_router(served: tuple[httpx.Client, Any, str]) -> None:
    """The lean read and its problems never reach the router; a read it does not take does."""
    http, app, base = served
    with router_calls(app) as entered:
        assert http.get(f"{base}/parameters/0x1017.0").status_code == 200
        missing = http.get(f"{base}/parameters/0x7FFF.0")
        assert missing.status_code == 404 and missing.headers["content-type"] == "application/problem+json"
        assert http.get("/api/health").status_code == 200
        assert entered == []
        assert http.get(f"{base}/parameters/0x1017.0", params={"transfer": "auto"}).status_code == 200
        assert entered == [f"{base}/parameters/0x1017.0"]


def test_the_lean_read_is_behind_the_same_gate(users: dict[str, str], hub_and_simulator: str) -> None:  # noqa: F811
    """Once an admin exists: no sign-in, no read (401, as the full path); a viewer's token reads."""
    app = create_app(buses=[hub_and_simulator])
    with serve_app(app) as url, httpx.Client(base_url=url, timeout=30) as http:
        admin = {"Authorization": f"Bearer {users['root']}"}
        session = http.get("/api/sessions", headers=admin).json()[0]["id"]
        http.post(f"/api/sessions/{session}/nodes", json={"node_id": NODE, "profile_id": PROFILE},
                  headers=admin).raise_for_status()
        path = f"/api/sessions/{session}/nodes/{NODE}/parameters/0x1017.0"
        anonymous, anonymous_full = http.get(path), http.get(path, params={"transfer": "auto"})
        assert anonymous.status_code == anonymous_full.status_code == 401
        assert anonymous.json() == anonymous_full.json()
        viewer = http.get(path, headers={"Authorization": f"Bearer {users['vera']}"})
        assert viewer.status_code == 200 and viewer.json()["ref"] == "0x1017"


def test_health_answers_without_solving_dependencies(served: tuple[httpx.Client, Any, str]) -> None:
    http, app, _ = served
    with full_path_refused(app, get_state):
        answer = http.get("/api/health")
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/json"
    body = answer.json()
    assert body["status"] == "ok" and body["sessions"] == 1 and body["version"] == __version__
    assert set(body) == set(http.get("/openapi.json").json()["components"]["schemas"]["Health"]["properties"])
