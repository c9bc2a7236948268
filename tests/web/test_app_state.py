"""App-wide state lives in the app (``web/state.AppState``, issue 29): two apps in one process (the tests make many)
share no accounts cache, sign-in limiter or cookie signer, and web/ and services/users/ keep no such state in module
globals."""

from __future__ import annotations

import ast
from pathlib import Path

from fastapi.testclient import TestClient

from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from drivebench.web.state import app_state

PACKAGE = Path(__file__).resolve().parents[2] / "backend" / "drivebench"
SCOPES = ("web", "services/users")
NOT_STATE = {
    "router", "planned_router",  # route tables (APIRouter), filled at import
    "log",  # loggers
    "templates",  # the Jinja environment: templates and filters, the same for every app
    "_hasher",  # argon2's parameters
    "_policies", "_decisions",  # weak maps keyed by the app: each app's own already
    "_trips",  # stops in flight (asyncio tasks kept until done, whichever app's socket started them)
    "_templates", "_templates_lock",  # the routers' routes as FastAPI built them, the same for every app
    "_serving",  # the app serving the request (a ContextVar: each request's own)
    "_building",  # one deferred route built at a time (a lock over the process's route tables)
}
"""Module-level names that hold objects but no app-wide state, and why."""


def _module_state(path: Path) -> list[str]:
    found = []
    for statement in ast.parse(path.read_text()).body:
        target, value = None, None
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
            target, value = statement.targets[0], statement.value
        elif isinstance(statement, ast.AnnAssign):
            target, value = statement.target, statement.value
        if not isinstance(target, ast.Name) or value is None or target.id in NOT_STATE:
            continue
        if target.id.lstrip("_")[:1].isupper() or target.id.startswith("__"):  # constants, types, __all__
            continue
        called = (value.func.id if isinstance(value.func, ast.Name) else value.func.attr
                  if isinstance(value.func, ast.Attribute) else "") if isinstance(value, ast.Call) else ""
        made = (isinstance(value, ast.Dict | ast.Set | ast.List)  # a literal, an instance, dict() / set() / list()
                or called.lstrip("_")[:1].isupper() or called in ("dict", "set", "list"))
        if made:
            found.append(f"{target.id} (line {statement.lineno})")
    return found


def test_web_and_users_keep_no_app_wide_state_in_module_globals() -> None:
    found = {str(path.relative_to(PACKAGE)): names for scope in SCOPES
             for path in sorted((PACKAGE / scope).rglob("*.py")) if (names := _module_state(path))}
    assert found == {}


def test_two_apps_in_one_process_keep_their_own_accounts(app_db_url: str) -> None:
    """Each app's users, verified tokens, sign-in limits and cookie signer are its own; a change made through one
    app's API counts there at once."""
    first, second = create_app(), create_app()
    with TestClient(first) as one, TestClient(second):
        kept = [(app_state(app).accounts, app_state(app).cookie_sessions) for app in (first, second)]
        assert kept[0][0] is not kept[1][0] and kept[0][1] is not kept[1][1]
        assert kept[0][0].sign_in is not kept[1][0].sign_in
        made = one.post("/api/users", json={"name": "root", "password": "root password", "role": "admin"})
        assert made.status_code == 201, made.text
        assert one.get("/api/sessions").status_code == 401  # signing in is on at once, on the app that made root
        user = app_state(first).accounts.account("root")
        assert user is not None and user.role is Role.ADMIN
