"""Signing in with name and password, shared by the API (``/api/auth/login``) and the sign-in page."""

from __future__ import annotations

import asyncio

from fastapi import Request

from drivebench.errors import Conflict
from drivebench.i18n import _
from drivebench.services.users import accounts
from drivebench.services.users.principals import Principal
from drivebench.web import access
from drivebench.web.state import app_state

FIRST_ADMIN = "drivebench users add admin --role admin"


def client_address(request: Request) -> str:
    return request.client.host if request.client else "unknown"


async def sign_in(request: Request, name: str, password: str) -> tuple[str, access.SignedIn, Principal]:
    """Check the password (rate-limited); the cookie value and session of the new sign-in."""
    state = app_state(request.app)
    if not await asyncio.to_thread(state.accounts.authentication_configured):
        raise Conflict(_("Signing in is not switched on: there is no admin user yet, so this server trusts the "
                         "local user."), hint=_("Create the first admin: {command}").format(command=FIRST_ADMIN))
    principal = await asyncio.to_thread(state.accounts.sign_in, name, password, client_address(request))
    user = await asyncio.to_thread(accounts.get_user, principal.name)
    value, signed_in = state.cookie_sessions.issue(user)
    return value, signed_in, principal
