"""Access control through the real app: sign-in, roles per route (every operation and websocket tried with every
role), CSRF, cross-site requests, API tokens. Users live in a database of each test's own."""

from __future__ import annotations

import re
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts, audit
from drivebench.services.users.principals import Role
from drivebench.web import access, access_policy
from drivebench.web.app import create_app
from drivebench.web.state import app_state
from tests.conftest import DEMO_PLANT, fresh_channel

PASSWORDS = {"root": "root password", "eve": "engineer password", "vera": "viewer password"}
ROLES = {"root": Role.ADMIN, "eve": Role.ENGINEER, "vera": Role.VIEWER}
BROWSER = {"Origin": "http://testserver", "Sec-Fetch-Site": "same-origin"}


@pytest.fixture
def own_db(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    url = f"sqlite:///{tmp_path / 'access.db'}"
    monkeypatch.setattr(settings, "database_url", url)
    monkeypatch.setattr(settings, "secret_key_file", tmp_path / "secret_key")
    database.upgrade_to_head(url)
    yield url
    database.dispose(url)


@pytest.fixture
def users(own_db: str) -> dict[str, str]:
    """root (admin), eve (engineer), vera (viewer); an API token of each, with the user's role."""
    for name, role in ROLES.items():
        accounts.create_user(name, PASSWORDS[name], role)
    return {name: accounts.issue_token(name, "test", role).secret for name, role in ROLES.items()}


@pytest.fixture
def app_client(own_db: str) -> Iterator[TestClient]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def sign_in(client: TestClient, name: str) -> str:
    """Sign in with the JSON API; the CSRF token of the new session."""
    answer = client.post("/api/auth/login", json={"name": name, "password": PASSWORDS[name]}, headers=BROWSER)
    assert answer.status_code == 200, answer.text
    return str(answer.json()["csrf_token"])


# --- no users: as before, but no other site may act -------------------------------------------------------------
def test_without_users_the_local_user_is_an_admin_and_needs_no_login(users_absent: None,
                                                                    app_client: TestClient) -> None:
    me = app_client.get("/api/auth/me", headers={"X-DriveBench-User": "otto"}).json()
    assert (me["name"], me["role"], me["via"], me["login_required"]) == ("otto", "admin", "local", False)
    assert app_client.get("/").status_code == 200
    answer = app_client.post("/api/auth/login", json={"name": "x", "password": "y"})
    assert answer.status_code == 409 and "drivebench users add admin --role admin" in answer.json()["hint"]


@pytest.fixture
def users_absent(own_db: str) -> None:
    assert not accounts.authentication_configured()


@pytest.mark.parametrize("headers", [{"Origin": "http://evil.example"}, {"Sec-Fetch-Site": "cross-site"},
                                     {"Origin": "http://127.0.0.1:9999", "Sec-Fetch-Site": "same-site"}])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_other_sites_cannot_start_anything_even_without_login(users_absent: None, app_client: TestClient,
                                                              headers: dict[str, str]) -> None:
    path = "/api/sessions/demo-plant/nodes/5/nmt"
    answer = app_client.post(path, json={"command": "start"}, headers=headers)
    assert answer.status_code == 403 and "Another web site may not change anything" in answer.json()["detail"]
    with pytest.raises(WebSocketDisconnect) as closed, \
            app_client.websocket_connect("/ws/sessions/demo-plant/nodes/5/control", headers=headers):
        pass
    assert closed.value.code == 4403
    assert app_client.get("/api/sessions", headers=headers).status_code == 200  # reading is not refused
    assert app_client.post(path, json={"command": "start"}, headers=BROWSER).status_code not in (401, 403)  # ours


# --- sign-in, sign-out, who am I --------------------------------------------------------------------------------
def test_login_required_once_an_admin_exists(users: dict[str, str], app_client: TestClient) -> None:
    assert app_client.get("/api/health").status_code == 200
    refused = app_client.get("/api/sessions")
    assert refused.status_code == 401 and refused.headers["content-type"] == "application/problem+json"
    assert "Sign in first" in refused.json()["detail"]
    page = app_client.get("/sessions/demo-plant/nodes/5", headers={"Accept": "text/html"}, follow_redirects=False)
    assert page.status_code == 303 and page.headers["location"] == "/login?next=/sessions/demo-plant/nodes/5"
    assert app_client.get("/login").status_code == 200 and app_client.get("/static/app.css").status_code == 200
    with pytest.raises(WebSocketDisconnect) as closed, app_client.websocket_connect("/ws/sessions/demo-plant/monitor"):
        pass
    assert closed.value.code == 4401


def test_login_me_logout_with_a_secure_cookie(users: dict[str, str], app_client: TestClient) -> None:
    answer = app_client.post("/api/auth/login", json={"name": "eve", "password": PASSWORDS["eve"]})
    cookie = answer.headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=strict" in cookie and "drivebench_session=" in cookie
    assert PASSWORDS["eve"] not in cookie
    me = app_client.get("/api/auth/me").json()
    assert (me["name"], me["role"], me["via"], me["login_required"]) == ("eve", "engineer", "login", True)
    csrf = me["csrf_token"]
    assert app_client.post("/api/auth/logout", headers={"X-CSRF-Token": csrf}).status_code == 204
    assert app_client.get("/api/auth/me").status_code == 401


def test_a_stolen_cookie_is_refused_after_logout(users: dict[str, str], app_client: TestClient) -> None:
    csrf = sign_in(app_client, "vera")
    stolen = app_client.cookies.get(access.SESSION_COOKIE)
    app_client.post("/api/auth/logout", headers={"X-CSRF-Token": csrf})
    assert app_client.get("/api/auth/me", cookies={access.SESSION_COOKIE: stolen}).status_code == 401


def test_wrong_passwords_lock_the_name_with_words(users: dict[str, str], app_client: TestClient) -> None:
    for _ in range(5):
        answer = app_client.post("/api/auth/login", json={"name": "vera", "password": "guess"})
        assert answer.status_code == 401 and answer.json()["detail"] == "Wrong user name or password."
    locked = app_client.post("/api/auth/login", json={"name": "vera", "password": PASSWORDS["vera"]})
    assert locked.status_code == 429 and int(locked.headers["Retry-After"]) > 0
    assert re.search(r"Too many failed sign-ins for vera: try again in \d+ seconds", locked.json()["detail"])


def test_new_password_ends_sessions(users: dict[str, str], app_client: TestClient) -> None:
    sign_in(app_client, "vera")
    accounts.set_password("vera", "a new password")
    app_state(app_client.app).accounts.forget()  # changed by "the CLI": this app reads it at once
    assert app_client.get("/api/auth/me").status_code == 401


# --- roles and CSRF -------------------------------------------------------------------------------------------------
def test_viewer_is_refused_writes_in_words_engineer_writes_and_is_audited(users: dict[str, str],
                                                                         app_client: TestClient) -> None:
    path = "/api/sessions/demo-plant/nodes/5/parameters/C00039/1"
    csrf = sign_in(app_client, "vera")
    refused = app_client.put(path, json={"value": 5}, headers={"X-CSRF-Token": csrf})
    assert refused.status_code == 403
    assert refused.json()["detail"] == ("Writing parameters needs the engineer role; you are signed in as vera "
                                        "(viewer).")
    csrf = sign_in(app_client, "eve")
    written = app_client.put(path, json={"value": 5}, headers={"X-CSRF-Token": csrf, "X-DriveBench-User": "mallory"})
    assert written.status_code == 200, written.text
    logged = [entry for entry in audit.entries(node_id=5) if entry.ref.startswith("C00039")]
    assert logged and {entry.user for entry in logged} == {"eve"}  # who signed in, not what a header claims


def test_csrf_token_is_required_for_cookie_sessions_not_for_tokens(users: dict[str, str],
                                                                   app_client: TestClient) -> None:
    path = "/api/sessions/demo-plant/monitor/pause"
    csrf = sign_in(app_client, "vera")
    missing = app_client.post(path)
    assert missing.status_code == 403 and "security token (CSRF)" in missing.json()["detail"]
    assert app_client.post(path, headers={"X-CSRF-Token": "wrong"}).status_code == 403
    assert app_client.post(path, headers={"X-CSRF-Token": csrf}).status_code < 400
    form = app_client.post("/logout", data={"csrf_token": csrf}, follow_redirects=False)  # a plain form
    assert form.status_code == 303 and form.headers["location"] == "/login"
    app_client.cookies.clear()
    with_token = app_client.post(path, headers={"Authorization": f"Bearer {users['vera']}"})
    assert with_token.status_code < 400


def test_a_form_s_csrf_field_is_read_and_the_form_still_reaches_the_route(users: dict[str, str],
                                                                          app_client: TestClient) -> None:
    csrf = sign_in(app_client, "root")
    for role, files in (("viewer", None), ("engineer", {"unused": ("a.txt", b"x")})):  # urlencoded, multipart
        answer = app_client.post("/ui/users/eve/role", data={"csrf_token": csrf, "role": role}, files=files)
        assert answer.status_code == 200, answer.text
        assert accounts.get_user("eve").role == Role.parse(role)
    refused = app_client.post("/ui/users/eve/role", data={"csrf_token": "wrong", "role": "viewer"})
    assert refused.status_code == 403 and accounts.get_user("eve").role == Role.ENGINEER


def test_tokens_act_with_their_role_and_revoked_tokens_are_refused(users: dict[str, str],
                                                                  app_client: TestClient) -> None:
    bearer = {"Authorization": f"Bearer {users['root']}"}
    created = app_client.post("/api/tokens", json={"name": "ci", "user": "eve", "role": "viewer"}, headers=bearer)
    assert created.status_code == 201 and created.json()["token"].startswith("dbt_")
    token = created.json()["token"]
    assert token not in app_client.get("/api/tokens", headers=bearer).text
    me = app_client.get("/api/auth/me", headers={"Authorization": f"Bearer {token}"}).json()
    assert (me["name"], me["role"], me["via"]) == ("eve", "viewer", "token")
    assert app_client.delete(f"/api/tokens/{created.json()['id']}", headers=bearer).status_code == 200
    assert app_client.get("/api/auth/me", headers={"Authorization": f"Bearer {token}"}).status_code == 401


def test_users_api_add_disable_reset(users: dict[str, str], app_client: TestClient) -> None:
    bearer = {"Authorization": f"Bearer {users['root']}"}
    added = app_client.post("/api/users", json={"name": "otto", "password": "otto password", "role": "engineer"},
                            headers=bearer)
    assert added.status_code == 201 and added.json()["role"] == "engineer"
    assert app_client.put("/api/users/otto/password", json={"password": "another one"},
                          headers=bearer).status_code == 204
    assert app_client.patch("/api/users/otto", json={"disabled": True}, headers=bearer).json()["disabled"]
    assert app_client.post("/api/auth/login", json={"name": "otto", "password": "another one"}).status_code == 401
    last = app_client.patch("/api/users/root", json={"role": "viewer"}, headers=bearer)
    assert last.status_code == 409 and "last enabled admin" in last.json()["detail"]
    assert app_client.get("/api/users", headers={"Authorization": f"Bearer {users['eve']}"}).status_code == 403


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_openapi_names_each_operation_s_role(users: dict[str, str], app_client: TestClient) -> None:
    spec = app_client.get("/openapi.json", headers={"Authorization": f"Bearer {users['vera']}"}).json()
    roles = {(method.upper(), path): op["x-drivebench-role"] for path, ops in spec["paths"].items()
             for method, op in ops.items()}
    assert roles[("PUT", "/api/sessions/{session_id}/nodes/{node_id}/parameters/{ref}")] == "engineer"
    assert roles[("POST", "/api/sessions")] == "admin" and roles[("GET", "/api/sessions")] == "viewer"
    assert roles[("POST", "/api/auth/login")] == "public"


def test_the_secret_key_file_is_private(own_db: str) -> None:
    key = access.secret_key()
    mode = stat.S_IMODE(Path(settings.secret_key_file).stat().st_mode)
    assert mode == 0o600 and len(key) > 40 and access.secret_key() == key


# --- every operation, every role ------------------------------------------------------------------------------------
PARAMETERS = {"session_id": "demo-plant", "node_id": "5", "ref": "C00039/1", "slot": "1", "direction": "rpdo",
              "number": "1", "family": "lenze-8400-motec", "network_id": "999", "set_id": "999",
              "download_id": "999", "job_id": "nosuchjob", "profile_id": "nosuchprofile", "command": "nosuch",
              "key": "nosuch", "run_id": "nosuch", "name": "nobody", "token_id": "999", "action": "retry",
              "token": "dbv_nosuch"}


def fill(template: str, link: str) -> str:
    def value(match: re.Match[str]) -> str:
        name = match.group(1).split(":")[0]
        if name == "token" and template.startswith(("/remote/", "/ws/remote/", "/api/remote/")):
            return link
        return PARAMETERS.get(name, "1")

    return re.sub(r"\{([^}]+)\}", value, template)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_every_operation_and_websocket_refuses_exactly_where_the_policy_says(users: dict[str, str],
                                                                            app_client: TestClient) -> None:
    app = app_client.app
    spec = app.openapi()  # type: ignore[attr-defined]
    operations = list(access_policy.operations(app))  # type: ignore[arg-type]
    walked = {(m, re.sub(r"\{(\w+):\w+\}", r"{\1}", t)) for m, t, _ in operations}
    in_spec = {(m.upper(), p) for p, ops in spec["paths"].items() for m in ops}
    assert in_spec <= walked, f"operations of the OpenAPI spec the walk misses: {in_spec - walked}"
    link = app_client.post("/api/share-links", json={"ttl_s": 600},
                           headers={"Authorization": f"Bearer {users['eve']}"}).json().get("token", "dbv_x")
    order = {"DELETE": 1}  # deletions last: they may remove what the other calls use
    wrong: list[str] = []
    tried = 0
    for who in (None, "vera", "eve", "root"):
        headers = {"Authorization": f"Bearer {users[who]}"} if who else {}
        role = ROLES.get(who or "")
        for method, template, rule in sorted(operations, key=lambda op: order.get(op[0], 0)):
            public = (method, template) in access_policy.PUBLIC
            expected = None if public else 401 if role is None else 403 if role < rule.role else None
            url = fill(template, link)
            status = _try(app_client, method, url, headers)
            tried += 1
            refused = status in (401, 403)
            if (expected is None and refused) or (expected is not None and status != expected):
                wrong.append(f"{who or 'anonymous'} {method} {url}: {status}, expected {expected or 'allowed'}")
    assert not wrong, "\n".join(wrong)
    assert tried >= 4 * 120


def _try(client: TestClient, method: str, url: str, headers: dict[str, str]) -> int:
    if method == access_policy.WEBSOCKET:
        try:
            with client.websocket_connect(url, headers=headers) as socket:
                socket.close()
        except WebSocketDisconnect as closed:
            return {4401: 401, 4403: 403}.get(closed.code, 200)
        except Exception:
            return 200
        return 200
    status = client.request(method, url, headers=headers, follow_redirects=False).status_code
    client.cookies.clear()  # a share link's page sets its viewer cookie; the next call must not carry it
    return status


def test_sign_in_form_goes_only_to_pages_of_this_server(users: dict[str, str], app_client: TestClient) -> None:
    for target, landing in [("/sessions/demo-plant/nodes/5", "/sessions/demo-plant/nodes/5"),
                            ("//evil.example/x", "/"), ("https://evil.example", "/")]:
        answer = app_client.post("/login", data={"name": "vera", "password": PASSWORDS["vera"], "next": target},
                                 follow_redirects=False)
        assert answer.status_code == 303 and answer.headers["location"] == landing
        app_client.cookies.clear()
    wrong = app_client.post("/login", data={"name": "vera", "password": "guess"})
    assert wrong.status_code == 401 and "Wrong user name or password." in wrong.text


def test_pages_and_htmx_get_their_own_refusals(users: dict[str, str], app_client: TestClient) -> None:
    sign_in(app_client, "vera")
    page = app_client.get("/users", headers={"Accept": "text/html"})
    assert page.status_code == 403 and "Managing users needs the admin role; you are signed in as vera" in page.text
    assert 'data-role="viewer"' in app_client.get("/", headers={"Accept": "text/html"}).text
    app_client.cookies.clear()
    fragment = app_client.post("/ui/sessions/demo-plant/scan", headers={"HX-Request": "true"})
    assert fragment.status_code == 401 and fragment.headers["HX-Redirect"] == "/login"
