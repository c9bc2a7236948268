"""Live node states: the node table of a session, pushed as an htmx out-of-band swap.

Message: the HTML of ``<table id="nodes-{session}">`` with ``hx-swap-oob="true"``, about twice a second when it
changed (the heartbeat ages change it at every look while nodes send heartbeats). The page holds a redraw back while a
button of the table is pressed (app.js): a redraw between press and release would lose the click.
"""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket

from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.bus.views import nodes_public
from drivebench.web.root import root_of
from drivebench.web.state import app_state
from drivebench.web.templating import templates
from drivebench.web.ws.node_socket import serve

router = APIRouter()
PERIOD_S = 0.5


@router.websocket("/ws/sessions/{session_id}/nodes")
async def node_states(websocket: WebSocket, session_id: str) -> None:
    await websocket.accept()
    manager = app_state(websocket.app).manager
    block = templates.env.get_template("plant.html").blocks["nodes_table"]

    async def receive() -> None:  # nothing is expected: it notices the client leaving while the table is unchanged
        while True:
            await websocket.receive_text()

    async def send() -> None:
        sent = ""
        while True:
            try:
                session = manager.get(session_id)
            except NotFound:
                await websocket.close(code=4404, reason=_("No open session '{session}'").format(session=session_id))
                return
            await session.refresh_states()
            context = templates.env.get_template("plant.html").new_context(
                {"session_id": session.id, "nodes": nodes_public(session), "bus_text": session.bus_text,
                 "bus_state": session.bus_state, "root": root_of(websocket.scope)})
            html = "".join(block(context)).replace(f'id="nodes-{session.id}"',
                                                   f'id="nodes-{session.id}" hx-swap-oob="true"', 1)
            if html != sent:
                await websocket.send_text(html)
                sent = html
            await asyncio.sleep(PERIOD_S)

    await serve(receive(), send())
