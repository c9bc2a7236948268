"""One session's monitor feed: builds each update once per distinct view among its live clients and queues the
messages per client (web/ws/monitor.py serves them; its docstring describes the messages). The app state keeps one
feed per session (``AppState.monitor_feeds``)."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any, Literal

from fastapi import WebSocket
from pydantic import BaseModel, Field

from drivebench import i18n
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import Monitor, MonitorFilter, MonitorView
from drivebench.services.monitoring.recording import recordings_for
from drivebench.web.monitor_filter import FilterBody

PERIOD_S = 0.1
TRACE_PER_UPDATE = 50
HELLO_TRACE_ROWS = 200
HELLO_TRACE_ROWS_MAX = 2000
"""A hello decodes its rows on the event loop: more would hold up the other clients' updates."""
COB_ROWS_PER_UPDATE = 512
COB_COLUMNS = ["text", "service", "node", "total", "rate", "share_percent", "last_age_s", "ids"]
TRACE_COLUMNS = ["seq", "time", "cob_id", "service", "group", "node", "dlc", "hex", "summary"]


class FeedClient:
    def __init__(self, websocket: WebSocket, view: MonitorView, hello_rows: int) -> None:
        self.locale = i18n.current()  # the connection's language: its messages are worded in it
        self.websocket = websocket
        self.view = view
        self.hello_rows = hello_rows
        self.pending: list[tuple[str, dict[str, Any]]] = []
        self.notices: list[str] = []
        self.ready = asyncio.Event()

    def notify(self, text: str) -> None:
        """A message outside the update stream (an error answer): sent as it is, before the next update."""
        self.notices.append(text)
        self.ready.set()

    def offer(self, text: str, message: dict[str, Any]) -> None:
        self.pending.append((text, message))
        if len(self.pending) > 50:  # a client this far behind keeps only the newest state
            del self.pending[:-50]
        self.ready.set()

    def replace(self, text: str, message: dict[str, Any]) -> None:
        """A hello or a view answer: what was queued for the old view is dropped."""
        self.pending = [(text, message)]
        self.ready.set()

    def take_notices(self) -> list[str]:
        notices, self.notices = self.notices, []
        if not self.pending:
            self.ready.clear()
        return notices

    def take(self) -> str:
        """The queued messages as one (the newest state, with every trace row and load point since)."""
        pending, self.pending = self.pending, []
        self.ready.clear()
        if len(pending) == 1:
            return pending[0][0]
        first = pending[0][1]
        merged = dict(pending[-1][1])
        merged["type"] = first["type"]
        if first["type"] != "update":  # a hello (or view answer) with the updates built after it
            merged.update({key: first[key] for key in ("view",) if key in first})
        messages = [message for _, message in pending if "history" in message]
        merged["history"] = [point for message in messages for point in message["history"]]
        trace = [row for message in messages for row in message["trace"]]
        keep = self.hello_rows if first["type"] == "hello" else TRACE_PER_UPDATE
        merged["trace_more"] = len(trace) > keep or any(message["trace_more"] for message in messages)
        merged["trace"] = trace[-keep:]
        return json.dumps(merged)


class Feed:
    """Builds the updates of one session's monitor while at least one client listens."""

    def __init__(self, session: Session, monitor: Monitor) -> None:
        self.session = session
        self.monitor = monitor
        self.clients: set[FeedClient] = set()
        self.seq = 0
        self.trace_seq = monitor.last_seq
        self.resets = monitor.resets
        self.history_until = 0.0
        self.task: asyncio.Task[None] | None = None
        self._hellos: dict[tuple[Any, ...], tuple[str, dict[str, Any]]] = {}
        self._hellos_seq = -1

    def message(self, kind: str, snapshot: dict[str, Any], history: list[tuple[float, float]],
                trace: list[dict[str, Any]], more: bool, recording: dict[str, Any] | None) -> dict[str, Any]:
        """One message; ``snapshot`` as the client's view shows it."""
        snapshot = dict(snapshot)
        cob_ids = snapshot["cob_ids"]
        if len(cob_ids) > COB_ROWS_PER_UPDATE:
            snapshot["cob_ids_cut"] = len(cob_ids)
            cob_ids = sorted(sorted(cob_ids, key=lambda row: -row["total"])[:COB_ROWS_PER_UPDATE],
                             key=lambda row: (row["extended"], row["cob_id"]))
        snapshot["cob_columns"] = COB_COLUMNS
        snapshot["cob_ids"] = [[row[column] for column in COB_COLUMNS] for row in cob_ids]
        return {"type": kind, "seq": self.seq, "server_time": time.time(), "snapshot": snapshot,
                "history": history, "trace_columns": TRACE_COLUMNS,
                "trace": [[row[column] for column in TRACE_COLUMNS] for row in trace], "trace_more": more,
                "recording": recording}

    def recording(self) -> dict[str, Any] | None:
        recorder = recordings_for(self.session).active
        return ({"name": recorder.path.name, "format": recorder.format, "frames": recorder.frames}
                if recorder else None)

    def _catch_up_reset(self) -> bool:
        """After a reset the trace starts again at sequence number 1."""
        if self.monitor.resets == self.resets:
            return False
        self.resets = self.monitor.resets
        self.trace_seq = 0
        return True

    def hello(self, view: MonitorView, rows: int = HELLO_TRACE_ROWS, locale: str = i18n.DEFAULT
              ) -> tuple[str, dict[str, Any]]:
        """A client's first message (and its answer to a new filter or a resume): the newest trace rows that pass
        its filter up to where the next update starts (so the client sees each telegram once), the whole load
        history, worded in ``locale``. Clients with the same view and language asking within one period share one
        hello."""
        if not self.clients:  # the feed was idle: start from now
            self.trace_seq = self.monitor.last_seq
            self.resets = self.monitor.resets
        self._catch_up_reset()
        if self._hellos_seq != self.seq:
            self._hellos, self._hellos_seq = {}, self.seq
        key = (locale, view.filter.key(), view.paused_at, view.epoch, rows, self.trace_seq, self.clients == set())
        cached = self._hellos.get(key)
        if cached is not None:
            return cached
        history = self.monitor.history()
        if not self.clients:
            self.history_until = history[-1][0] if history else 0.0
        trace, _ = self.monitor.trace_since(0, rows, until=self.trace_seq, view=view)
        with i18n.using(locale):
            snapshot = self.monitor.snapshot(view)
        message = self.message("hello", snapshot, history, trace, False, self.recording())
        message["view"] = {"filter": view.filter.as_dict(), "paused": view.paused}
        self._hellos[key] = json.dumps(message), message
        return self._hellos[key]

    def tick(self) -> None:
        if self._catch_up_reset():
            for client in list(self.clients):
                if not client.view.paused:
                    client.replace(*self.hello(client.view, client.hello_rows, client.locale))
            return
        after, newest = self.trace_seq, self.monitor.last_seq
        self.trace_seq = newest
        history = self.monitor.history(self.history_until)
        if history:
            self.history_until = history[-1][0]
        groups: dict[tuple[Any, ...], list[FeedClient]] = {}
        for client in list(self.clients):
            if not client.view.paused:
                groups.setdefault((client.locale, client.view.filter.key()), []).append(client)
        if not groups:
            return
        self.seq += 1
        live = self.monitor.live_snapshot()
        recording = self.recording()
        for (locale, _filter), members in groups.items():
            view = members[0].view
            rows, _more = self.monitor.trace_since(after, TRACE_PER_UPDATE + 1, until=newest, view=view)
            with i18n.using(locale):  # one message per language and filter: the bus and flood sentences in it
                snapshot = self.monitor.view_snapshot(live, view)
            message = self.message("update", snapshot, history, rows[-TRACE_PER_UPDATE:],
                                   len(rows) > TRACE_PER_UPDATE, recording)
            text = json.dumps(message)
            for client in members:
                client.offer(text, message)

    def change_view(self, client: FeedClient, request: ViewRequest) -> None:
        """Apply a client's view message and queue the answer (see the module docstring)."""
        view = client.view
        if request.rows is not None:
            client.hello_rows = request.rows
        if request.filter is not None:
            body = request.filter
            self.monitor.set_filter(MonitorFilter(set(body.nodes), set(body.services), body.cob_min, body.cob_max),
                                    view)
        if request.paused is True and not view.paused:
            self.monitor.pause(view)
            if request.filter is None:
                answer = {"type": "view", "view": {"filter": view.filter.as_dict(), "paused": True}}
                client.replace(json.dumps(answer), answer)
                return
        if request.paused is False:
            self.monitor.resume(view)
        client.replace(*self.hello(view, client.hello_rows, client.locale))

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


class ViewRequest(BaseModel):
    """A client's message: its own filter, pause, hello size."""

    type: Literal["view"]
    filter: FilterBody | None = None
    paused: bool | None = None
    rows: int | None = Field(None, ge=1, le=HELLO_TRACE_ROWS_MAX)
