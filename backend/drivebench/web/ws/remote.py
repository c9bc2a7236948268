"""Live network health for the remote diagnostics view.

Message: the HTML of ``<div id="remote-health">`` with ``hx-swap-oob="true"``, once a second. Rendered from the
consumers' cached state, so any number of viewers add no bus traffic.
"""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from drivebench.errors import DriveBenchError
from drivebench.web.pages.remote import health_context
from drivebench.web.state import app_state
from drivebench.web.templating import templates

router = APIRouter()
PERIOD_S = 1.0


@router.websocket("/ws/remote/{token}")
async def remote_health(websocket: WebSocket, token: str) -> None:
    state = app_state(websocket.app)
    try:
        link = await asyncio.to_thread(state.share_links.check, token)
    except DriveBenchError as exc:
        await websocket.close(code=4401, reason=exc.detail[:120])
        return
    await websocket.accept()
    template = templates.env.get_template("remote_view.html")
    block = template.blocks["health"]
    try:
        while True:
            try:
                await asyncio.to_thread(state.share_links.check, token)
            except DriveBenchError as exc:
                await websocket.close(code=4401, reason=exc.detail[:120])
                return
            html = "".join(block(template.new_context(health_context(state, link.shows))))
            await websocket.send_text(html.replace('id="remote-health"', 'id="remote-health" hx-swap-oob="true"', 1))
            await asyncio.sleep(PERIOD_S)
    except (WebSocketDisconnect, RuntimeError):
        return
