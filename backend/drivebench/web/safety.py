"""Who acts on a node, as the safety services see it: the panel (browser tab or API client), the writer of the node
lease, and the confirmation an action that can move a drive carries; all of it in one
:class:`~drivebench.services.params.write_context.WriteContext` (the route dependency :data:`WriteCtxDep`) that a
route hands to every service call that can write.

A browser tab names itself with ``X-DriveBench-Client`` (app.js sets it on every htmx request; the Control tab sends
the same id as ``X-Drive-Panel``); websockets pass it as ``?client=``. Without one, a client is one panel per host.
The confirmation is the ``X-DriveBench-Confirm`` header, the ``confirm`` query parameter or a body field, with the
values it confirms (the ``X-DriveBench-Confirm-Values`` header or the ``confirm_values`` body field).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated

from fastapi import Depends
from starlette.requests import HTTPConnection

from drivebench.i18n import N_
from drivebench.services.control import drive_guard
from drivebench.services.control.drive_guard import panel_of
from drivebench.services.params.write_context import LOCAL_USER, Confirmation, Panel, WriteContext, Writer
from drivebench.web.identity import principal_of
from drivebench.web.root import route_path

AUDIT_USER = "audit_user"
"""``scope["state"]`` key: the name the audit log gives the request's writes (``web/gate.py`` sets it from sign-in)."""

# Where a write comes from, as the node lease names it to others: kept English (N_) in the lease, each reader sees
# it in their own language (the template calls _() on it). (path part, from a page, from the API)
WHERE = [("/parameter-sets", N_("Parameter sets"), N_("Parameter sets API")),
         ("/parameters", N_("Parameters tab"), N_("Parameters API")), ("/pdo", N_("PDO tab"), N_("PDO API")),
         ("/control", N_("Control tab"), N_("Control API")), ("/nmt", N_("NMT"), N_("NMT API")),
         ("/commands", N_("device commands"), N_("device commands API")),
         ("/lease", N_("node lease"), N_("node lease API")),
         ("/program", N_("program download"), N_("program download API"))]


def client_id(conn: HTTPConnection) -> str | None:
    return (conn.headers.get("x-drivebench-client") or conn.headers.get("x-drive-panel")
            or conn.query_params.get("client") or conn.query_params.get("panel") or None)


def panel_for(conn: HTTPConnection) -> Panel:
    principal = principal_of(conn)
    if principal.via != "local":  # signed in: the holder shown to others is who signed in, not what a header says
        panel = panel_of(conn.client.host if conn.client else None, client_id(conn), principal.name)
        # and the panel is that user's: another user (a viewer) sending the same tab id from the same host is
        # another panel, so only the user (and client) that armed a drive keeps it alive
        return replace(panel, key=f"{panel.key}|user:{principal.name}")
    operator = conn.headers.get("x-drive-operator") or conn.query_params.get("operator") or principal.name
    return panel_of(conn.client.host if conn.client else None, client_id(conn), operator)


def where_of(path: str) -> str:
    for part, page, api in WHERE:
        if part in path:
            return page if path.startswith("/ui/") else api
    return N_("the API")


def writer_for(conn: HTTPConnection) -> Writer:
    return Writer(name=principal_of(conn).name, client=panel_for(conn).key, where=where_of(route_path(conn.scope)))


def audit_user(conn: HTTPConnection) -> str:
    """Who the audit log names for the request's writes: who signed in, else the local user (no login configured)."""
    return conn.scope.get("state", {}).get(AUDIT_USER) or LOCAL_USER


async def current_audit_user(conn: HTTPConnection) -> str:
    """Route dependency: :func:`audit_user` (a route that stores something in the user's name)."""
    return audit_user(conn)


async def current_writer(conn: HTTPConnection) -> Writer:
    """Route dependency: the writer of the node lease this request writes as."""
    return writer_for(conn)


def write_context_of(conn: HTTPConnection, origin: str = "parameters") -> WriteContext:
    """What the writes of this request (and of the jobs it starts) are checked against: its user, panel, lease
    writer, and the confirmation the header or query carries (a route with a ``confirm`` body field adds it with
    :meth:`WriteContext.confirming`)."""
    return WriteContext.request(user=audit_user(conn), origin=origin, panel=panel_for(conn), writer=writer_for(conn),
                                confirmation=confirmation(conn))


async def write_context(conn: HTTPConnection) -> WriteContext:
    """Route dependency: :func:`write_context_of` the request."""
    return write_context_of(conn)


def confirmation(conn: HTTPConnection, given: object = None, values: object = None) -> Confirmation | None:
    """The confirmation an action carries: the node it names (a body field, else the ``X-DriveBench-Confirm``
    header, else the ``confirm`` query parameter) and the values it repeats (a body field, else the
    ``X-DriveBench-Confirm-Values`` header: a JSON object)."""
    node = given if given is not None and given is not False else (
        conn.headers.get("x-drivebench-confirm") or conn.query_params.get("confirm"))
    if isinstance(values, str):
        values = drive_guard.parse_values(values)
    if values is None:
        values = drive_guard.parse_values(conn.headers.get("x-drivebench-confirm-values"))
    if node is None and values is None:
        return None
    return Confirmation(node, values)


async def current_panel(conn: HTTPConnection) -> Panel:
    """Route dependency: ``panel_for`` without a thread-pool hop."""
    return panel_for(conn)


PanelDep = Annotated[Panel, Depends(current_panel)]
WriterDep = Annotated[Writer, Depends(current_writer)]
WriteCtxDep = Annotated[WriteContext, Depends(write_context)]
AuditUserDep = Annotated[str, Depends(current_audit_user)]
