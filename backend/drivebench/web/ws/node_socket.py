"""What the live sockets of one node share: opening on a session's node (4404 when there is none) and running
the socket's reader and writer until either ends."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Coroutine
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect

from drivebench.errors import NotFound
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.web.state import app_state


async def open_session(websocket: WebSocket, session_id: str) -> Session | None:
    """Accept the socket and find its session; an unknown session closes it with code 4404 (None)."""
    await websocket.accept()
    try:
        return app_state(websocket.app).manager.get(session_id)
    except NotFound as exc:
        await websocket.close(code=4404, reason=exc.shown_detail()[:120])
        return None


async def open_node(websocket: WebSocket, session_id: str, node_id: int) -> tuple[Session, SessionNode] | None:
    """Accept the socket and find its session's node; an unknown session or node closes it with code 4404 (None)."""
    session = await open_session(websocket, session_id)
    if session is None:
        return None
    try:
        return session, session.node(node_id)
    except NotFound as exc:
        await websocket.close(code=4404, reason=exc.shown_detail()[:120])
        return None


async def serve(receive: Coroutine[Any, Any, None], send: Coroutine[Any, Any, None],
                closed: Callable[[], None] | None = None) -> None:
    """Run the socket's reader and writer until one of them ends (the client went away, a send failed), call
    ``closed`` at once, then cancel both and wait for them."""
    tasks = [asyncio.create_task(receive), asyncio.create_task(send)]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        if closed is not None:
            closed()
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, RuntimeError, Exception):
                await task
