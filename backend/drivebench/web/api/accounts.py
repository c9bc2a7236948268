"""Signing in and out, who am I, users and API tokens (JSON). Which role each route needs: ``web/access_policy``."""

from __future__ import annotations

import asyncio
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field

from drivebench.errors import NotAuthenticated
from drivebench.i18n import _
from drivebench.services.users import accounts
from drivebench.services.users.principals import Principal, Role
from drivebench.web import access, live_access
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import RowId, StateDep
from drivebench.web.identity import PrincipalDep
from drivebench.web.problems import problem_body
from drivebench.web.sign_in import FIRST_ADMIN, client_address, sign_in
from drivebench.web.state import app_state

router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["accounts"])

RoleName = Annotated[str, Field(pattern="^(viewer|engineer|admin)$", description="viewer, engineer or admin")]


class Credentials(BaseModel):
    name: str = Field(min_length=1, max_length=60)
    password: str = Field(min_length=1, max_length=accounts.MAX_PASSWORD_LENGTH)


class Me(BaseModel):
    name: str
    role: str
    via: str
    """``login`` (cookie session), ``token``, ``link`` (remote diagnostics) or ``local`` (no login configured)."""
    login_required: bool
    csrf_token: str | None = None
    """Send it as ``X-CSRF-Token`` with every unsafe request of this cookie session."""


class UserOut(BaseModel):
    name: str
    role: str
    created: datetime
    disabled: bool


class NewUser(BaseModel):
    name: str = Field(min_length=1, max_length=60)
    password: str = Field(min_length=accounts.MIN_PASSWORD_LENGTH, max_length=accounts.MAX_PASSWORD_LENGTH)
    role: RoleName


class UserChange(BaseModel):
    role: RoleName | None = None
    disabled: bool | None = None


class NewPassword(BaseModel):
    password: str = Field(min_length=accounts.MIN_PASSWORD_LENGTH, max_length=accounts.MAX_PASSWORD_LENGTH)


class OwnPassword(NewPassword):
    current_password: str = Field(min_length=1, max_length=accounts.MAX_PASSWORD_LENGTH)


class TokenOut(BaseModel):
    id: int
    name: str
    owner: str
    role: str
    hint: str
    created: datetime
    last_used: datetime | None
    revoked: datetime | None


class IssuedTokenOut(TokenOut):
    token: str
    """The token itself: shown this once, not stored. Send it as ``Authorization: Bearer dbt_…``."""


class NewToken(BaseModel):
    name: str = Field(min_length=1, max_length=120)
    role: RoleName


class NewTokenFor(NewToken):
    user: str = Field(min_length=1, max_length=60)


def user_out(user: accounts.User) -> UserOut:
    return UserOut(name=user.name, role=user.role.label, created=user.created, disabled=user.disabled)


def token_out(token: accounts.ApiToken) -> TokenOut:
    return TokenOut(id=token.id, name=token.name, owner=token.owner, role=token.role.label, hint=token.hint,
                    created=token.created, last_used=token.last_used, revoked=token.revoked)


def issued_out(issued: accounts.IssuedToken) -> IssuedTokenOut:
    return IssuedTokenOut(**token_out(issued.token).model_dump(), token=issued.secret)


def me_of(request: Request, principal: Principal) -> Me:
    view = access.access_of(request)
    return Me(name=principal.name, role=principal.role.label, via=principal.via,
              login_required=bool(view and view.login), csrf_token=view.csrf if view else None)


def locked_response(exc: accounts.LoginLocked, path: str) -> JSONResponse:
    body = problem_body(exc, path)
    body["status"] = 429
    return JSONResponse(body, status_code=429, media_type="application/problem+json",
                        headers={"Retry-After": str(exc.retry_after_s)})


@router.post("/auth/login", response_model=Me, responses={401: {}, 409: {}, 429: {}})
async def login(request: Request, credentials: Credentials) -> Response:
    """Sign in with name and password: sets the session cookie and returns the CSRF token of the session."""
    try:
        value, signed_in, principal = await sign_in(request, credentials.name, credentials.password)
    except accounts.LoginLocked as exc:
        return locked_response(exc, request.url.path)
    me = Me(name=principal.name, role=principal.role.label, via="login", login_required=True,
            csrf_token=signed_in.csrf)
    response = JSONResponse(me.model_dump())
    access.set_session_cookie(response, request, value)
    return response


@router.post("/auth/logout", status_code=204)
async def logout(request: Request) -> Response:
    view = access.access_of(request)
    if view is not None and view.session is not None:
        app_state(request.app).cookie_sessions.sign_out(view.session)
        await live_access.recheck_now(request.app)
    response = Response(status_code=204)
    access.clear_session_cookie(response, request)
    return response


@router.get("/auth/me", response_model=Me)
async def me(request: Request, principal: PrincipalDep) -> Me:
    """Who this request acts as (with no login configured: the local user, an admin)."""
    return me_of(request, principal)


def _signed_in_user(principal: Principal) -> str:
    if principal.via not in ("login", "token"):
        raise NotAuthenticated(_("Only a signed-in user has a password and API tokens of their own."),
                               hint=_("Signing in starts when an admin exists: {command}").format(
                                   command=FIRST_ADMIN))
    return principal.name


@router.put("/auth/password", status_code=204, responses={401: {}, 429: {}})
async def change_own_password(request: Request, body: OwnPassword, principal: PrincipalDep) -> Response:
    """A wrong ``current_password`` counts as a failed sign-in (the same limit per name and address: 429)."""
    name = _signed_in_user(principal)
    try:
        await asyncio.to_thread(app_state(request.app).accounts.sign_in, name, body.current_password,
                                client_address(request))
    except accounts.LoginLocked as exc:
        return locked_response(exc, request.url.path)
    await asyncio.to_thread(app_state(request.app).accounts.set_password, name, body.password)
    await live_access.recheck_now(request.app)
    return Response(status_code=204)


@router.get("/auth/tokens", response_model=list[TokenOut])
async def own_tokens(principal: PrincipalDep) -> list[TokenOut]:
    name = _signed_in_user(principal)
    return [token_out(t) for t in await asyncio.to_thread(accounts.list_tokens, name)]


@router.post("/auth/tokens", response_model=IssuedTokenOut, status_code=201)
async def create_own_token(body: NewToken, principal: PrincipalDep) -> IssuedTokenOut:
    """A token for your scripts, with your role or a lower one. The token is in this answer only."""
    name = _signed_in_user(principal)
    role = min(Role.parse(body.role), principal.role)  # a token request cannot mint more than it has
    return issued_out(await asyncio.to_thread(
        lambda: accounts.issue_token(name, body.name, role, parent=principal.token_id)))


@router.delete("/auth/tokens/{token_id}", response_model=TokenOut)
async def revoke_own_token(request: Request, token_id: RowId, principal: PrincipalDep, state: StateDep) -> TokenOut:
    name = _signed_in_user(principal)
    revoked = await asyncio.to_thread(lambda: state.accounts.revoke_token(token_id, owner=name))
    await live_access.recheck_now(request.app)
    return token_out(revoked)


# --- admin: users and every token -----------------------------------------------------------------------------
@router.get("/users", response_model=list[UserOut])
async def list_users() -> list[UserOut]:
    return [user_out(u) for u in await asyncio.to_thread(accounts.list_users)]


@router.post("/users", response_model=UserOut, status_code=201)
async def create_user(body: NewUser, state: StateDep) -> UserOut:
    return user_out(await asyncio.to_thread(state.accounts.create_user, body.name, body.password,
                                            Role.parse(body.role)))


@router.get("/users/{name}", response_model=UserOut)
async def get_user(name: str) -> UserOut:
    return user_out(await asyncio.to_thread(accounts.get_user, name))


@router.patch("/users/{name}", response_model=UserOut)
async def change_user(request: Request, name: str, body: UserChange, state: StateDep) -> UserOut:
    """Change the role or disable / enable; the last enabled admin cannot be demoted or disabled. Answered once the
    user's live connections that may no longer stay open are closed and the drives they held stopped."""
    def change() -> accounts.User:
        user = accounts.get_user(name)
        if body.role is not None:
            user = state.accounts.set_role(name, Role.parse(body.role))
        if body.disabled is not None:
            user = state.accounts.set_disabled(name, body.disabled)
        return user

    changed = await asyncio.to_thread(change)
    await live_access.recheck_now(request.app)
    return user_out(changed)


@router.put("/users/{name}/password", status_code=204)
async def reset_password(request: Request, name: str, body: NewPassword, state: StateDep) -> Response:
    """Set a new password: the user's sessions and API tokens end (and their live connections, at once)."""
    await asyncio.to_thread(lambda: state.accounts.set_password(name, body.password, end_tokens=True))
    await live_access.recheck_now(request.app)
    return Response(status_code=204)


@router.get("/tokens", response_model=list[TokenOut])
async def list_tokens() -> list[TokenOut]:
    return [token_out(t) for t in await asyncio.to_thread(accounts.list_tokens)]


@router.post("/tokens", response_model=IssuedTokenOut, status_code=201)
async def create_token(body: NewTokenFor, principal: PrincipalDep) -> IssuedTokenOut:
    """A token for a user's scripts (role no higher than the user's). The token is in this answer only; one made
    with a token ends with that token."""
    return issued_out(await asyncio.to_thread(
        lambda: accounts.issue_token(body.user, body.name, Role.parse(body.role), parent=principal.token_id)))


@router.delete("/tokens/{token_id}", response_model=TokenOut)
async def revoke_token(request: Request, token_id: RowId, state: StateDep) -> TokenOut:
    revoked = await asyncio.to_thread(state.accounts.revoke_token, token_id)
    await live_access.recheck_now(request.app)
    return token_out(revoked)
