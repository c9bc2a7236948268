"""The principal of a request or websocket.

The access-control middleware puts it into ``scope["state"]["principal"]``. Without one (no login configured,
the server on 127.0.0.1) the local user acts with every right, named by the ``X-DriveBench-User`` header or the
operating-system user; a remote-diagnostics share link acts as a viewer.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends
from starlette.requests import HTTPConnection

from drivebench.services.users import audit
from drivebench.services.users.principals import Principal, Role


def principal_of(conn: HTTPConnection) -> Principal:
    principal = conn.scope.get("state", {}).get("principal")
    if isinstance(principal, Principal):
        return principal
    link = conn.scope.get("state", {}).get("viewer")
    if link is not None:
        return Principal(f"remote link {getattr(link, 'label', '') or 'viewer'}", Role.VIEWER, via="link")
    name = (conn.headers.get("x-drivebench-user") or "").strip()[:120] or audit.LOCAL_USER
    return Principal(name, Role.ADMIN, via="local")


async def current_principal(conn: HTTPConnection) -> Principal:
    """Route dependency: ``principal_of`` without a thread-pool hop (a plain ``def`` dependency runs in one)."""
    return principal_of(conn)


PrincipalDep = Annotated[Principal, Depends(current_principal)]
