"""The sign-in page, signing out, and the Users screen (users, roles, passwords, API tokens)."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web import access, live_access
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import RowId
from drivebench.web.problems import problem_body
from drivebench.web.root import under_root
from drivebench.web.sign_in import FIRST_ADMIN, sign_in
from drivebench.web.state import app_state
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
ROLES = [role.label for role in Role]


def _role(text: str) -> Role:
    try:
        return Role.parse(text)
    except ValueError as exc:
        raise InvalidValue(str(exc)) from None


def _safe_next(target: str | None) -> str:
    """Only a path of this server (never ``//elsewhere`` or ``https://elsewhere``) after signing in."""
    if not target or not target.startswith("/") or target.startswith("//") or "\\" in target:
        return "/"
    return target


@router.get("/login", response_class=HTMLResponse)
async def login_page(request: Request, next: str = "/") -> Response:
    view = access.access_of(request)
    if view is not None and view.session is not None:
        return RedirectResponse(under_root(request.scope, _safe_next(next)), status_code=303)
    configured = await asyncio.to_thread(_accounts(request).authentication_configured)
    return templates.TemplateResponse(request, "login.html", {"next": _safe_next(next), "configured": configured,
                                                              "first_admin": FIRST_ADMIN, "active": None})


@router.post("/login", response_class=HTMLResponse)
async def login_form(request: Request, name: str = Form(""), password: str = Form(""),
                     next: str = Form("/")) -> Response:
    try:
        if not name.strip() or not password:
            raise InvalidValue(_("Enter your user name and your password."))
        value, _signed_in, _principal = await sign_in(request, name, password)
    except DriveBenchError as exc:
        body = problem_body(exc, request.url.path)
        status = 429 if isinstance(exc, accounts.LoginLocked) else int(body["status"])  # type: ignore[call-overload]
        context = {"next": _safe_next(next), "configured": True, "first_admin": FIRST_ADMIN, "name": name,
                   "problem": body, "active": None}
        return templates.TemplateResponse(request, "login.html", context, status_code=status)
    response = RedirectResponse(under_root(request.scope, _safe_next(next)), status_code=303)
    access.set_session_cookie(response, request, value)
    return response


@router.post("/logout")
async def logout(request: Request) -> Response:
    view = access.access_of(request)
    if view is not None and view.session is not None:
        app_state(request.app).cookie_sessions.sign_out(view.session)
    response = RedirectResponse(under_root(request.scope, "/login"), status_code=303)
    access.clear_session_cookie(response, request)
    return response


# --- the Users screen (admin) -----------------------------------------------------------------------------------
def _accounts(request: Request) -> accounts.Accounts:
    return app_state(request.app).accounts


def _context(known: accounts.Accounts, **extra: Any) -> dict[str, Any]:
    return {"users": accounts.list_users(), "tokens": accounts.list_tokens(), "roles": ROLES,
            "configured": known.authentication_configured(), "first_admin": FIRST_ADMIN, "active": "users", **extra}


async def _render(request: Request, block: str | None = None, status: int = 200, **extra: Any) -> Response:
    """The page, or one block; a change of the users also refreshes the token form's list of users (out of band)."""
    context = await asyncio.to_thread(_context, _accounts(request), block=block, **extra)
    if block == "users":
        return templates.TemplateResponse(request, "users.html", context, block_names=["users", "tokens"],
                                          status_code=status)
    return templates.TemplateResponse(request, "users.html", context, block_name=block, status_code=status)


@router.get("/users", response_class=HTMLResponse)
async def users_page(request: Request) -> Response:
    return await _render(request)


async def _act(request: Request, block: str, action: Any, done: str) -> Response:
    """Run ``action`` in a worker thread; the block again with ``done`` or the error inside it."""
    try:
        result = await asyncio.to_thread(action)
    except DriveBenchError as exc:
        body = problem_body(exc, request.url.path)
        return await _render(request, block, status=int(body["status"]), problem=body)  # type: ignore[call-overload]
    await live_access.recheck_now(request.app)  # a user disabled or demoted: their live connections end now
    issued = result if isinstance(result, accounts.IssuedToken) else None
    return await _render(request, block, done=done, issued=issued)


@router.post("/ui/users", response_class=HTMLResponse)
async def add_user(request: Request, name: str = Form(""), role: str = Form("viewer"), password: str = Form(""),
                   password_again: str = Form("")) -> Response:
    def add() -> accounts.User:
        if password != password_again:
            raise InvalidValue(_("The two passwords differ: type the same password twice."))
        return _accounts(request).create_user(name, password, _role(role))

    return await _act(request, "users", add, _("Added {name} ({role}).").format(name=name.strip(), role=role))


@router.post("/ui/users/{name}/disable", response_class=HTMLResponse)
async def disable_user(request: Request, name: str) -> Response:
    return await _act(request, "users", lambda: _accounts(request).set_disabled(name, True),
                      _("Disabled {name}: they can no longer sign in, and their tokens stop working.").format(
                          name=name))


@router.post("/ui/users/{name}/enable", response_class=HTMLResponse)
async def enable_user(request: Request, name: str) -> Response:
    return await _act(request, "users", lambda: _accounts(request).set_disabled(name, False),
                      _("Enabled {name}.").format(name=name))


@router.post("/ui/users/{name}/role", response_class=HTMLResponse)
async def change_role(request: Request, name: str, role: str = Form(...)) -> Response:
    return await _act(request, "users", lambda: _accounts(request).set_role(name, _role(role)),
                      _("{name} is now {role}.").format(name=name, role=role))


@router.post("/ui/users/{name}/password", response_class=HTMLResponse)
async def reset_password(request: Request, name: str, password: str = Form("")) -> Response:
    return await _act(request, "users", lambda: _accounts(request).set_password(name, password, end_tokens=True),
                      _("New password set for {name}; their open sessions and API tokens have ended.").format(
                          name=name))


@router.post("/ui/tokens", response_class=HTMLResponse)
async def create_token(request: Request, name: str = Form(""), user: str = Form(""),
                       role: str = Form("viewer")) -> Response:
    return await _act(request, "tokens", lambda: accounts.issue_token(user, name, _role(role)),
                      _("Token '{name}' created for {user}. Copy it now: it is not shown again.").format(
                          name=name.strip(), user=user))


@router.post("/ui/tokens/{token_id}/revoke", response_class=HTMLResponse)
async def revoke_token(request: Request, token_id: RowId) -> Response:
    return await _act(request, "tokens", lambda: _accounts(request).revoke_token(token_id),
                      _("Token revoked: scripts using it are refused from now on."))
#FIXME
