"""API tokens end with what they came from (issue 28 item 13), through the real HTTP API: a token minted with a
token is refused once its parent is revoked (or its parent's owner disabled), also when the parent is revoked
after minting; an admin's password reset ends the user's tokens with their sessions."""

from __future__ import annotations

from fastapi.testclient import TestClient

from tests.web.test_access import app_client, own_db, users

__all__ = ["app_client", "own_db", "users"]  # fixtures shared with test_access


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _me(client: TestClient, token: str) -> int:
    return client.get("/api/auth/me", headers=_bearer(token)).status_code


def test_a_token_minted_by_a_token_ends_with_its_parent(users: dict[str, str], app_client: TestClient) -> None:
    parent = app_client.post("/api/auth/tokens", json={"name": "parent", "role": "engineer"},
                             headers=_bearer(users["eve"])).json()
    child = app_client.post("/api/auth/tokens", json={"name": "child", "role": "viewer"},
                            headers=_bearer(parent["token"]))
    assert child.status_code == 201, child.text
    grandchild = app_client.post("/api/auth/tokens", json={"name": "grandchild", "role": "viewer"},
                                 headers=_bearer(child.json()["token"])).json()
    assert _me(app_client, child.json()["token"]) == _me(app_client, grandchild["token"]) == 200
    revoked = app_client.delete(f"/api/auth/tokens/{parent['id']}", headers=_bearer(users["eve"]))
    assert revoked.status_code == 200, revoked.text
    assert _me(app_client, parent["token"]) == 401
    assert _me(app_client, child.json()["token"]) == 401
    assert _me(app_client, grandchild["token"]) == 401
    listed = {t["name"]: t for t in app_client.get("/api/auth/tokens", headers=_bearer(users["eve"])).json()}
    assert listed["child"]["revoked"] and listed["grandchild"]["revoked"]  # the list says so too
    assert _me(app_client, users["eve"]) == 200  # the token that was not involved


def test_a_token_an_admin_s_token_made_for_another_user_ends_with_it(users: dict[str, str],
                                                                    app_client: TestClient) -> None:
    admin_token = app_client.post("/api/auth/tokens", json={"name": "automation", "role": "admin"},
                                  headers=_bearer(users["root"])).json()
    made = app_client.post("/api/tokens", json={"name": "ci", "user": "eve", "role": "viewer"},
                           headers=_bearer(admin_token["token"]))
    assert made.status_code == 201 and _me(app_client, made.json()["token"]) == 200
    assert app_client.delete(f"/api/tokens/{admin_token['id']}", headers=_bearer(users["root"])).status_code == 200
    assert _me(app_client, made.json()["token"]) == 401


def test_an_admin_password_reset_ends_the_user_s_tokens(users: dict[str, str], app_client: TestClient) -> None:
    assert _me(app_client, users["eve"]) == 200
    reset = app_client.put("/api/users/eve/password", json={"password": "a new password"},
                           headers=_bearer(users["root"]))
    assert reset.status_code == 204, reset.text
    assert _me(app_client, users["eve"]) == 401
    assert all(t["revoked"] for t in app_client.get("/api/tokens", headers=_bearer(users["root"])).json()
               if t["owner"] == "eve")
    assert _me(app_client, users["root"]) == 200  # the admin's own token is not the user's
    signed_in = app_client.post("/api/auth/login", json={"name": "eve", "password": "a new password"})
    assert signed_in.status_code == 200  # the user signs in with the new password and makes new tokens
