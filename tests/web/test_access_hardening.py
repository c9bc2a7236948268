"""Access-control holes found by an outside test (issue 16), each through the real HTTP API and websockets:
DNS rebinding (Host and Origin judged against the server's own names), the password change's rate limit, sessions
that end for good when a user is disabled, share links (URL from the server's own address, listed without tokens
and only to those who make them) and what a link token may read (cached state only: never a frame to a drive)."""

from __future__ import annotations

import re

import can
import pytest
from fastapi.testclient import TestClient
from httpx import Response
from starlette.websockets import WebSocketDisconnect

from drivebench.config import settings
from drivebench.web import access, access_policy
from drivebench.web.viewer import LINK_READS
from tests.web.test_access import BROWSER, PARAMETERS, PASSWORDS, app_client, own_db, sign_in, users

__all__ = ["app_client", "own_db", "users"]  # fixtures shared with test_access

EVIL = {"Host": "evil.example:8301", "Origin": "http://evil.example:8301"}
START_5 = ("/api/sessions/demo-plant/nodes/5/nmt", {"command": "start"})


# --- 3: DNS rebinding -------------------------------------------------------------------------------------------
def test_a_rebound_name_reaches_nothing_without_login(own_db: str, app_client: TestClient) -> None:
    path, body = START_5
    refused = app_client.post(path, json=body, headers=EVIL)
    assert refused.status_code == 400 and refused.headers["content-type"] == "application/problem+json"
    assert "'evil.example:8301', which is not a name of this server" in refused.json()["detail"]
    assert "--allowed-host" in refused.json()["hint"]
    for reading in ("/api/audit", "/api/sessions/demo-plant/nodes/5/control", "/api/health"):
        assert app_client.get(reading, headers=EVIL).status_code == 400, reading
    page = app_client.get("/", headers={**EVIL, "Accept": "text/html"})
    assert page.status_code == 400 and page.headers["content-type"].startswith("text/plain")
    assert "DNS rebinding" in page.text and "<html" not in page.text
    for socket in ("/ws/sessions/demo-plant/nodes/5/control", "/ws/sessions/demo-plant/monitor"):
        with pytest.raises(WebSocketDisconnect) as closed, app_client.websocket_connect(socket, headers=EVIL):
            pass
        assert closed.value.code == 4400, socket
    plant = app_client.app.state.drivebench.plants["demo-plant"]  # type: ignore[attr-defined]
    assert plant.nodes[5].state.name != "OPERATIONAL"  # nothing started


@pytest.mark.parametrize("host", ["127.0.0.1:8301", "localhost:8301", "[::1]:8301", "localhost", "testserver"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_loopback_names_with_any_port_are_ours(own_db: str, app_client: TestClient, host: str) -> None:
    assert app_client.get("/api/sessions", headers={"Host": host}).status_code == 200


def test_origin_is_judged_against_the_names_not_against_host(own_db: str, app_client: TestClient,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "allowed_hosts", [*settings.allowed_hosts, "bench.example"])
    path = "/api/sessions/demo-plant/monitor/pause"
    ours = app_client.post(path, headers={"Host": "bench.example", "Origin": "https://bench.example"})
    assert ours.status_code == 200, ours.text
    behind_a_proxy = app_client.post(path, headers={"Host": "127.0.0.1:8301", "Origin": "https://bench.example"})
    assert behind_a_proxy.status_code == 200, behind_a_proxy.text
    for origin in ("http://evil.example:8301", "http://127.0.0.1:9999", "null", "http://bench.example.evil.example"):
        refused = app_client.post(path, headers={"Host": "127.0.0.1:8301", "Origin": origin})
        assert refused.status_code == 403 and "Another web site" in refused.json()["detail"], origin
    assert app_client.get("/api/sessions", headers={"Host": "bench.example:8443"}).status_code == 200
    assert app_client.get("/api/sessions", headers={"Host": "bench.example.evil.example"}).status_code == 400


# --- 6: the password change counts as a sign-in ----------------------------------------------------------------
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_wrong_current_passwords_lock_the_password_change(users: dict[str, str], app_client: TestClient) -> None:
    csrf = sign_in(app_client, "vera")
    change = {"X-CSRF-Token": csrf}
    for _ in range(5):
        wrong = app_client.put("/api/auth/password", json={"current_password": "guess", "password": "new password"},
                               headers=change)
        assert wrong.status_code == 401, wrong.text
    locked = app_client.put("/api/auth/password", json={"current_password": PASSWORDS["vera"],
                                                        "password": "new password"}, headers=change)
    assert locked.status_code == 429 and int(locked.headers["Retry-After"]) > 0
    assert re.search(r"Too many failed sign-ins for vera: try again in \d+ seconds", locked.json()["detail"])
    assert app_client.post("/api/auth/login", json={"name": "vera", "password": PASSWORDS["vera"]}).status_code == 429


# --- 7: disabling ends every session for good --------------------------------------------------------------------
def test_disabled_then_enabled_user_s_old_cookie_stays_dead(users: dict[str, str], app_client: TestClient) -> None:
    sign_in(app_client, "eve")
    old_cookie = app_client.cookies.get(access.SESSION_COOKIE)
    assert app_client.get("/api/auth/me").status_code == 200
    app_client.cookies.clear()
    root = {"Authorization": f"Bearer {users['root']}"}
    assert app_client.patch("/api/users/eve", json={"disabled": True}, headers=root).json()["disabled"]
    assert not app_client.patch("/api/users/eve", json={"disabled": False}, headers=root).json()["disabled"]
    assert app_client.get("/api/auth/me", cookies={access.SESSION_COOKIE: old_cookie}).status_code == 401
    sign_in(app_client, "eve")  # a new sign-in works
    newer = app_client.cookies.get(access.SESSION_COOKIE)
    app_client.cookies.clear()
    assert app_client.patch("/api/users/eve", json={"role": "viewer"}, headers=root).json()["role"] == "viewer"
    assert app_client.get("/api/auth/me", cookies={access.SESSION_COOKIE: newer}).status_code == 401


# --- 9 and 10: share links -------------------------------------------------------------------------------------------
def test_share_link_url_comes_from_the_server_not_from_host(own_db: str, app_client: TestClient,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "allowed_hosts", [*settings.allowed_hosts, "bench.example"])
    made = app_client.post("/api/share-links", json={"ttl_minutes": 5}, headers={"Host": "bench.example:8301"})
    assert made.status_code == 201
    assert made.json()["url"] == f"http://testserver/remote/{made.json()['token']}"  # where the client connected
    monkeypatch.setattr(settings, "public_url", "https://drivebench.plant.example/")
    made = app_client.post("/api/share-links", json={"ttl_minutes": 5}, headers={"Host": "localhost:8301"})
    assert made.json()["url"] == f"https://drivebench.plant.example/remote/{made.json()['token']}"


def test_only_link_makers_list_links_and_never_see_a_token(users: dict[str, str], app_client: TestClient) -> None:
    eve = {"Authorization": f"Bearer {users['eve']}"}
    made = app_client.post("/api/share-links", json={"ttl_minutes": 5, "label": "service"}, headers=eve).json()
    token = made["token"]
    listed = app_client.get("/api/share-links", headers=eve)
    assert listed.status_code == 200 and token not in listed.text
    assert [(link["id"], link["hint"], link["label"]) for link in listed.json()] == [
        (made["id"], token[:8], "service")]
    vera = app_client.get("/api/share-links", headers={"Authorization": f"Bearer {users['vera']}"})
    assert vera.status_code == 403 and "needs the engineer role; you are signed in as vera" in vera.json()["detail"]
    sign_in(app_client, "vera")
    page = app_client.get("/remote", headers={"Accept": "text/html"})
    assert page.status_code == 200 and made["id"] not in page.text and token[:8] not in page.text
    app_client.cookies.clear()
    assert app_client.get("/api/health/nodes", headers={"Authorization": f"Bearer {token}"}).status_code == 200
    assert app_client.get(f"/remote/{token}").status_code == 200  # the link itself still works
    app_client.cookies.clear()
    assert app_client.delete(f"/api/share-links/{made['id']}", headers=eve).status_code == 204
    assert app_client.get("/api/health/nodes", headers={"Authorization": f"Bearer {token}"}).status_code == 401


# --- 11: a link token reads cached state only --------------------------------------------------------------------
def sdo_requests(wire: can.BusABC) -> list[str]:
    """The SDO requests to any node on the wire since the last call (COB-ID 0x600 + node id)."""
    seen = []
    while (frame := wire.recv(timeout=0)) is not None:
        if 0x601 <= frame.arbitration_id <= 0x67F:
            seen.append(f"{frame.arbitration_id:#x} {frame.data.hex()}")
    return seen


def test_no_route_that_reads_a_drive_is_open_to_a_link(app_db_url: str, client: TestClient,
                                                       wire: can.BusABC) -> None:
    """Every GET route and page, found from the app (the same list as the OpenAPI spec plus the pages): what makes
    a drive answer for a local engineer is refused for a link token, and nothing a link asks puts an SDO request
    on the bus; the remote view and its stream still work."""
    spec = client.get("/openapi.json").json()["paths"]
    token = client.post("/api/share-links", json={"ttl_minutes": 5}).json()["token"]
    link = {"Authorization": f"Bearer {token}"}
    gets = [template for method, template, _ in access_policy.operations(client.app)  # type: ignore[arg-type]
            if method == "GET"]
    assert {*gets, "/static"} >= LINK_READS, "a route a link may read is gone: update LINK_READS"
    assert {re.sub(r"\{(\w+):\w+\}", r"{\1}", t) for t in gets} >= {p for p, ops in spec.items() if "get" in ops}
    reading_drives, wrong = [], []
    for template in gets:
        url = re.sub(r"\{([^}:]+)(:\w+)?\}", lambda m: {**PARAMETERS, "token": token}.get(m.group(1), "1"),
                     template)
        sdo_requests(wire)
        client.get(url, follow_redirects=False)
        if sdo_requests(wire):
            reading_drives.append(url)
        answer = client.get(url, headers=link, follow_redirects=False)
        client.cookies.clear()
        if (frames := sdo_requests(wire)):
            wrong.append(f"{url}: a link made the drives answer ({answer.status_code}): {frames[:3]}")
        elif url in reading_drives and not _kept_out(answer, token):
            wrong.append(f"{url}: reads a drive, but a link gets {answer.status_code}")
    assert not wrong, "\n".join(wrong)
    assert {"/api/sessions/demo-plant/nodes/5/parameters/C00039/1", "/api/sessions/demo-plant/nodes/5/heartbeat",
            "/api/sessions/demo-plant/nodes/5/pdos"} <= set(reading_drives), reading_drives
    view = client.get(f"/remote/{token}")
    assert view.status_code == 200 and "read-only view" in view.text
    assert client.get("/api/health/nodes").json()[0]["nodes"]
    with client.websocket_connect(f"/ws/remote/{token}") as stream:
        assert 'id="remote-health"' in stream.receive_text()
    assert not sdo_requests(wire)


def _kept_out(answer: Response, token: str) -> bool:
    """Refused in words (the API), or led to the remote view (a page)."""
    if answer.status_code == 303:
        return answer.headers["location"] == f"/remote/{token}"
    return answer.status_code == 403 and "never makes a drive answer" in answer.json()["detail"]


def test_a_link_holder_cannot_read_a_parameter(app_db_url: str, client: TestClient) -> None:
    token = client.post("/api/share-links", json={"ttl_minutes": 5}).json()["token"]
    refused = client.get("/api/sessions/demo-plant/nodes/5/parameters/C00039/1",
                         headers={"Authorization": f"Bearer {token}", **BROWSER})
    assert refused.status_code == 403 and "never makes a drive answer over the bus" in refused.json()["detail"]
