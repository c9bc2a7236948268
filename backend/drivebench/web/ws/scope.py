"""A session's scope recording, live: ``/ws/sessions/{session}/scope`` sends JSON messages as soon as there is
something new and the viewer's previous message went out (at most one per :data:`MIN_INTERVAL_S`); what comes while
a message waits for that, or while the viewer lags (a send that waits for the network), goes out in one message:

* ``{"type": "state", ...}`` (the run's status: state, source and its real rate, channels, trigger, captures, the
  stored ``recording_id``) first and whenever it changes; ``{"type": "state", "state": "none"}`` while the session
  has had no recording;
* ``{"type": "rows", "rows": [[sample, time_s, value per channel ...], ...]}``: the samples since the last message
  (a viewer who opens during a run gets the last ones first);
* ``{"type": "events", "events": [{"time_s", "node", "kind", "text"}, ...]}``: markers (EMCY, NMT, the source's).

Everything in words (the restore list, the markers' texts) is in the socket's language: the gate holds it for the
socket's tasks, and the run keeps its texts as :class:`~drivebench.i18n.Text` until each socket sends them.

A new recording of the session is followed at once. An unknown session closes the socket with code 4404.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import weakref
from typing import Any

from fastapi import APIRouter, WebSocket

from drivebench.services.scope import runs
from drivebench.web.identity import principal_of
from drivebench.web.state import app_state
from drivebench.web.ws.node_socket import open_session, serve

router = APIRouter()
MIN_INTERVAL_S = 0.01
"""The least time between two messages to one viewer: rows that come faster (a 1 ms SYNC) go out together, at most
this late (the design's 100 ms display latency leaves room); a row after a quieter time goes out at once."""
IDLE_S = 0.5


def rows_message(encoded: weakref.WeakKeyDictionary[Any, tuple[tuple[int, int, int], str]], run: runs.ScopeRun,
                 rows: list[list[Any]]) -> str:
    """The ``rows`` message of ``rows``, encoded once for every viewer who takes the same rows at once (viewers who
    keep up take the same ones: a run's rows come in sample order, so the first and last sample and the count name
    them)."""
    key = (rows[0][0], rows[-1][0], len(rows))
    cached = encoded.get(run)
    if cached is None or cached[0] != key:
        cached = encoded[run] = key, json.dumps({"type": "rows", "rows": rows}, separators=(",", ":"),
                                                 ensure_ascii=False)
    return cached[1]


@router.websocket("/ws/sessions/{session_id}/scope")
async def scope(websocket: WebSocket, session_id: str) -> None:
    session = await open_session(websocket, session_id)
    if session is None:
        return

    user = principal_of(websocket).name
    encoded = app_state(websocket.app).scope_messages

    async def receive() -> None:
        while True:
            await websocket.receive_text()

    async def send() -> None:
        run: runs.ScopeRun | None = None
        key = ""
        first = True
        loop = asyncio.get_running_loop()
        sent = 0.0
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
                if not (watcher.changed or watcher.rows or watcher.events):
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(IDLE_S):
                            await watcher.wake.wait()
                    watcher.wake.clear()
                    continue  # what came, or a new run
                if (wait := sent + MIN_INTERVAL_S - loop.time()) > 0:
                    await asyncio.sleep(wait)  # what comes meanwhile goes out with it
                watcher.wake.clear()
                sent = loop.time()
                if watcher.changed:
                    watcher.changed = False
                    await websocket.send_json({"type": "state", **run.status()})
                if watcher.rows:
                    rows, watcher.rows = watcher.rows, []
                    await websocket.send_text(rows_message(encoded, run, rows))
                if watcher.events:
                    events, watcher.events = watcher.events, []
                    await websocket.send_json({"type": "events", "events": [runs.event_json(e) for e in events]})
        finally:
            if run is not None:
                run.unwatch(key)

    await serve(receive(), send())
