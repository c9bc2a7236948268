"""Live drive panel of one node, and its keep-alive.

``/ws/sessions/{session}/nodes/{node}/control`` sends ``{"type": "status", "status": DriveStatus, "actuals":
[ActualValue], "t": unix time}`` every :data:`PERIOD_S` (``{"type": "error", "detail": ...}`` when a read fails),
from the node's one status poll all its panels share (:mod:`drivebench.services.control.status_poll`).
The query names the panel: ``?panel=<id>&operator=<name>`` (the same id and name the panel's API calls send as
``X-Drive-Panel`` / ``X-Drive-Operator``; without them, one panel per host). Every message the client sends (e.g.
``{"cmd": "keepalive"}``) is a keep-alive of the node if this panel holds it. When the holder's last socket closes
while the node is armed, the server sends quick stop at once; a watcher's socket closing changes nothing. Each
status says who holds the drive and whether it is this panel (``holder``, ``you_hold``). An unknown session or node
closes the socket with code 4404; a node or user with too many panels open sends an ``error`` saying so and closes
with code 4429 (:mod:`drivebench.web.ws.control_limits`; never the panel that holds the node).

``/ws/sessions/{session}/keepalive?client=<tab id>`` is a page's keep-alive for what it started (NMT start on the
Plant page, RPDOs on the PDO tab): every message the client sends (``{"cmd": "keepalive"}``, at least every 2 s)
keeps alive every node that tab holds in the session; when its last such socket closes, those nodes are stopped
(cyclic RPDOs end, quick stop, NMT pre-operational for the nodes the tool started) at their keep-alive deadline,
at most 2 s later, unless the same tab reconnects first (the next page of an in-app navigation keeps them
running). The tab's node write leases end with its last such socket. The server answers each message with
``{"type": "held", "nodes": [5], "not_held": [{"node": 3, "holder": "..."}]}`` (``not_held``: armed nodes another
user or client holds, which this keep-alive does not reach).
"""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from drivebench.i18n import N_, Text
from drivebench.services.control import drive_control, status_poll
from drivebench.services.control.drive_guard import Guard
from drivebench.services.params import node_lease
from drivebench.web.identity import principal_of
from drivebench.web.safety import panel_for
from drivebench.web.ws import control_limits
from drivebench.web.ws.node_socket import open_node, open_session, serve

router = APIRouter()
PERIOD_S = status_poll.PERIOD_S
_trips: set[asyncio.Task[None]] = set()


@router.websocket("/ws/sessions/{session_id}/nodes/{node_id}/control")
async def control(websocket: WebSocket, session_id: str, node_id: int) -> None:
    if (opened := await open_node(websocket, session_id, node_id)) is None:
        return
    session, node = opened
    guard = drive_control.guard_for(session)
    panel = panel_for(websocket)
    try:
        seat = control_limits.admit(session, node_id, panel, principal_of(websocket).name)
    except control_limits.Refused as exc:
        await websocket.send_json({"type": "error", "detail": str(exc)})
        await websocket.close(code=control_limits.TOO_MANY, reason=control_limits.close_reason(str(exc)))
        return
    guard.opened(node_id, panel)

    async def receive() -> None:
        while True:
            await websocket.receive_text()
            guard.keepalive(node_id, panel)

    async def send() -> None:
        async with status_poll.watching(session, node) as watcher:
            while True:
                message = await watcher.next()
                if message["type"] == "status":  # the shared poll reads as nobody's panel: this one may hold it
                    holder = guard.holder(node_id)
                    you_hold = holder is not None and holder.panel.key == panel.key
                    message = {**message, "status": {**message["status"], "you_hold": you_hold}}
                await websocket.send_json(message)

    def closed() -> None:
        seat.leave()
        if guard.closed(node_id, panel):
            _trip(guard, node_id, Text(N_("the control panel holding the drive disconnected")))

    await serve(receive(), send(), closed)


def _trip(guard: Guard, node_id: int, reason: str) -> None:
    """Stop the node in its own task: it must complete even when the handler is being cancelled."""
    trip = asyncio.get_running_loop().create_task(guard.trip(node_id, reason))
    _trips.add(trip)
    trip.add_done_callback(_trips.discard)


@router.websocket("/ws/sessions/{session_id}/keepalive")
async def keepalive(websocket: WebSocket, session_id: str) -> None:
    session = await open_session(websocket, session_id)
    if session is None:
        return
    guard = drive_control.guard_for(session)
    panel = panel_for(websocket)
    guard.client_opened(panel)
    leases = node_lease.leases(session)
    leases.client_opened(panel.key)
    try:
        while True:
            await websocket.receive_text()
            await websocket.send_json({"type": "held", "nodes": guard.keepalive_all(panel),
                                       "not_held": [{"node": node, "holder": holder}
                                                    for node, holder in guard.held_elsewhere(panel).items()]})
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        guard.client_closed(panel)  # its nodes stop at their deadline unless the same tab reconnects at once
        leases.client_closed(panel.key)  # and its write leases end
