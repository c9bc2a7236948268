"""Who acts on a node, as the safety services see it: the panel (browser tab or API client), the writer of the node
lease, and the confirmation an action that can move a drive carries.

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
from drivebench.services.control.drive_guard import Confirmation, Panel, panel_of
from drivebench.services.params import node_lease
from drivebench.services.params.node_lease import Writer
from drivebench.web.identity import principal_of

# Where a write comes from, as the node lease names it to others: kept English (N_) in the lease, each reader sees
# it in their own language (the template calls _() on it). (path part, from a page, from the API)
WHERE = [("/parameter-sets", N_("Parameter sets"), N_("Parameter sets API")),
         ("/parameters", N_("Parameters tab"), N_("Parameters API")), ("/pdo", N_("PDO tab"), N_("PDO API")),
         ("/control", N_("Control tab"), N_("Control API")), ("/nmt", N_("NMT"), N_("NMT API")),
         ("/commands", N_("device commands"), N_("device commands API")),
         ("/lease", N_("node lease"), N_("node lease API"))]


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
    return Writer(name=principal_of(conn).name, client=panel_for(conn).key, where=where_of(conn.url.path))


async def acting_writer(conn: HTTPConnection) -> Writer:
    """Router dependency: the writes of this request (and the jobs it starts) are this writer's, from this panel,
    with the confirmation the header or query carries (a route with a ``confirm`` body field adds it)."""
    writer = writer_for(conn)
    node_lease.writing_as(writer)
    drive_guard.acting_as(panel_for(conn), confirmation(conn))
    return writer


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
WriterDep = Annotated[Writer, Depends(acting_writer)]
ACTING = Depends(acting_writer)
