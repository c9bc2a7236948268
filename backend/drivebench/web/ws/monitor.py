"""Live monitor of a session over a websocket, about 10 updates a second.

One feed per session builds each update once (snapshot, new load points, new trace rows, serialised once) and
hands it to every client; a client that falls behind gets the next update merged with the ones it missed
(trace rows and load points are kept, counters are the newest), so a slow browser never slows the others or
the bus. Rendering on the client is throttled to animation frames.

Messages (JSON text), one schema:

``{"type": "hello" | "update", "seq": int, "server_time": float (epoch s, when built),
   "snapshot": <GET /api/sessions/{id}/monitor without "trace", except "cob_ids" (below)>,
   "history": [[epoch s, load %], ...]   # completed seconds since the previous message (hello: the last 10 min)
   "trace_columns": [...], "trace": [<trace row>, ...],  # decoded telegrams since the previous message that
                                                         # pass the filter
   "trace_more": bool,                   # more telegrams came than one message carries (TRACE_PER_UPDATE)
   "recording": {"name", "format", "frames"} | null}``

To keep updates small (each is compressed once per client), rows travel as arrays:
``trace`` rows in the order of ``trace_columns``: ``["seq", "time", "cob_id", "service", "group", "node", "dlc",
"hex", "summary"]`` (the REST trace rows are objects and also carry ``text``, ``cob_id service node N: summary``);
``snapshot.cob_ids`` rows in the order of ``snapshot.cob_columns``: ``["text", "service", "node", "total", "rate",
"share_percent", "last_age_s"]``; more than COB_ROWS_PER_UPDATE COB-IDs send the busiest, with ``cob_ids_cut``
the full count.
The socket closes with code 4404 when the session does not exist (or is closed).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from drivebench.errors import NotFound
from drivebench.services.monitor import Monitor, monitor_for
from drivebench.services.recording import recordings_for
from drivebench.services.sessions import Session

router = APIRouter()
PERIOD_S = 0.1
TRACE_PER_UPDATE = 50
HELLO_TRACE_ROWS = 200
COB_ROWS_PER_UPDATE = 512
COB_COLUMNS = ["text", "service", "node", "total", "rate", "share_percent", "last_age_s"]
TRACE_COLUMNS = ["seq", "time", "cob_id", "service", "group", "node", "dlc", "hex", "summary"]


class _Client:
    def __init__(self, websocket: WebSocket) -> None:
        self.websocket = websocket
        self.pending: list[tuple[str, dict[str, Any]]] = []
        self.ready = asyncio.Event()

    def offer(self, text: str, message: dict[str, Any]) -> None:
        self.pending.append((text, message))
        if len(self.pending) > 50:  # a client this far behind keeps only the newest state
            del self.pending[:-50]
        self.ready.set()

    def take(self) -> str:
        pending, self.pending = self.pending, []
        self.ready.clear()
        if len(pending) == 1:
            return pending[0][0]
        merged = dict(pending[-1][1])
        merged["history"] = [point for _, message in pending for point in message["history"]]
        trace = [row for _, message in pending for row in message["trace"]]
        merged["trace_more"] = len(trace) > TRACE_PER_UPDATE or any(m["trace_more"] for _, m in pending)
        merged["trace"] = trace[-TRACE_PER_UPDATE:]
        return json.dumps(merged)


class Feed:
    """Builds the updates of one session's monitor while at least one client listens."""

    def __init__(self, session: Session, monitor: Monitor) -> None:
        self.session = session
        self.monitor = monitor
        self.clients: set[_Client] = set()
        self.seq = 0
        self.trace_seq = monitor.last_seq
        self.history_until = 0.0
        self.task: asyncio.Task[None] | None = None
        self._hello: tuple[int, str] | None = None

    def message(self, kind: str, history: list[tuple[float, float]], trace: list[dict[str, Any]],
                more: bool) -> dict[str, Any]:
        """One message; an update advances ``seq``, a hello carries the seq of the update it precedes."""
        snapshot = dict(self.monitor.snapshot())
        cob_ids = snapshot["cob_ids"]
        if len(cob_ids) > COB_ROWS_PER_UPDATE:
            snapshot["cob_ids_cut"] = len(cob_ids)
            cob_ids = sorted(sorted(cob_ids, key=lambda row: -row["total"])[:COB_ROWS_PER_UPDATE],
                             key=lambda row: (row["extended"], row["cob_id"]))
        snapshot["cob_columns"] = COB_COLUMNS
        snapshot["cob_ids"] = [[row[column] for column in COB_COLUMNS] for row in cob_ids]
        recorder = recordings_for(self.session).active
        recording = ({"name": recorder.path.name, "format": recorder.format, "frames": recorder.frames}
                     if recorder else None)
        if kind == "update":
            self.seq += 1
        return {"type": kind, "seq": self.seq, "server_time": time.time(), "snapshot": snapshot,
                "history": history, "trace_columns": TRACE_COLUMNS,
                "trace": [[row[column] for column in TRACE_COLUMNS] for row in trace], "trace_more": more,
                "recording": recording}

    def hello(self) -> str:
        """The first message of a client: the newest trace rows up to where the next update starts (so the client
        sees each telegram once), the whole load history. Clients joining within one period share one hello."""
        if not self.clients:  # the feed was idle: start from now
            self.trace_seq = self.monitor.last_seq
            self._hello = None
        elif self.monitor.last_seq < self.trace_seq:  # reset since the last update
            self.trace_seq = 0
        if self._hello is not None and self._hello[0] == self.seq:
            return self._hello[1]
        history = self.monitor.history()
        if not self.clients:
            self.history_until = history[-1][0] if history else 0.0
        rows, _ = self.monitor.trace_since(0, HELLO_TRACE_ROWS, until=self.trace_seq)
        text = json.dumps(self.message("hello", history, rows, False))
        self._hello = (self.seq, text)
        return text

    def tick(self) -> None:
        if self.monitor.last_seq < self.trace_seq:  # reset since the last update
            self.trace_seq = 0
        rows, self.trace_seq = self.monitor.trace_since(self.trace_seq, TRACE_PER_UPDATE + 1)
        history = self.monitor.history(self.history_until)
        if history:
            self.history_until = history[-1][0]
        message = self.message("update", history, rows[-TRACE_PER_UPDATE:], len(rows) > TRACE_PER_UPDATE)
        text = json.dumps(message)
        for client in list(self.clients):
            client.offer(text, message)

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while self.clients:
            self.tick()
            next_at += PERIOD_S
            delay = next_at - loop.time()
            if delay < 0:  # fell behind (a loaded machine): skip, never burst
                next_at = loop.time()
                delay = 0
            await asyncio.sleep(delay)


def _feed(websocket: WebSocket, session: Session) -> Feed:
    feeds: dict[str, Feed] | None = getattr(websocket.app.state, "monitor_feeds", None)
    if feeds is None:
        feeds = {}
        websocket.app.state.monitor_feeds = feeds
    feed = feeds.get(session.id)
    if feed is None or feed.session is not session:
        feed = feeds[session.id] = Feed(session, monitor_for(session))
    return feed


async def _receive_until_closed(websocket: WebSocket) -> None:
    while True:
        await websocket.receive_text()


async def _send_loop(client: _Client) -> None:
    while True:
        await client.ready.wait()
        await client.websocket.send_text(client.take())


@router.websocket("/ws/sessions/{session_id}/monitor")
async def monitor_stream(websocket: WebSocket, session_id: str) -> None:
    await websocket.accept()
    try:
        session = websocket.app.state.drivebench.manager.get(session_id)
    except NotFound:
        await websocket.close(code=4404, reason=f"No open session '{session_id}'")
        return
    feed = _feed(websocket, session)
    client = _Client(websocket)
    sender: asyncio.Task[None] | None = None
    try:
        hello = feed.hello()
        feed.clients.add(client)  # before the first await: updates built from now on queue behind the hello
        if feed.task is None or feed.task.done():
            feed.task = asyncio.create_task(feed.run())
        await websocket.send_text(hello)
        sender = asyncio.create_task(_send_loop(client))
        # The client says nothing; receiving notices the disconnect.
        receiver = asyncio.create_task(_receive_until_closed(websocket))
        done, _ = await asyncio.wait({sender, receiver}, return_when=asyncio.FIRST_COMPLETED)
        receiver.cancel()
        for task in done:
            with contextlib.suppress(WebSocketDisconnect, RuntimeError, asyncio.CancelledError):
                task.result()
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        feed.clients.discard(client)
        if sender is not None:
            sender.cancel()
