"""A session's scope recording, live: ``/ws/sessions/{session}/scope`` sends JSON messages, batched (at most one per
:data:`MIN_INTERVAL_S`):

* ``{"type": "state", ...}`` (the run's status: state, source and its real rate, channels, trigger, captures, the
  stored ``recording_id``) first and whenever it changes; ``{"type": "state", "state": "none"}`` while the session
  has had no recording;
* ``{"type": "rows", "rows": [[sample, time_s, value per channel ...], ...]}``: the samples since the last message
  (a viewer who opens during a run gets the last ones first);
* ``{"type": "events", "events": [{"time_s", "node", "kind", "text"}, ...]}``: markers (EMCY, NMT, the source's).

A new recording of the session is followed at once. An unknown session closes the socket with code 4404.
"""

from __future__ import annotations

import asyncio
import contextlib

from fastapi import APIRouter, WebSocket

from drivebench.services.scope import runs
from drivebench.web.identity import principal_of
from drivebench.web.ws.node_socket import open_session, serve

router = APIRouter()
MIN_INTERVAL_S = 0.04
IDLE_S = 0.5


@router.websocket("/ws/sessions/{session_id}/scope")
async def scope(websocket: WebSocket, session_id: str) -> None:
    session = await open_session(websocket, session_id)
    if session is None:
        return

    user = principal_of(websocket).name

    async def receive() -> None:
        while True:
            await websocket.receive_text()

    async def send() -> None:
        run: runs.ScopeRun | None = None
        key = ""
        first = True
        try:
            while True:
                latest = runs.latest(session)
                if latest is not run or first:
                    first = False
                    if run is not None:
                        run.unwatch(key)
                    run = latest
                    if run is None:
                        await websocket.send_json({"type": "state", "state": "none"})
                    else:
                        key, _watcher = run.watch(user)
                if run is None:
                    await asyncio.sleep(IDLE_S)
                    continue
                watcher = run.watchers[key]
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(watcher.wake.wait(), IDLE_S)
                watcher.wake.clear()
                if watcher.changed:
                    watcher.changed = False
                    await websocket.send_json({"type": "state", **run.status()})
                if watcher.rows:
                    rows, watcher.rows = watcher.rows, []
                    await websocket.send_json({"type": "rows", "rows": rows})
                if watcher.events:
                    events, watcher.events = watcher.events, []
                    await websocket.send_json({"type": "events", "events": events})
                await asyncio.sleep(MIN_INTERVAL_S)
        finally:
            if run is not None:
                run.unwatch(key)

    await serve(receive(), send())
