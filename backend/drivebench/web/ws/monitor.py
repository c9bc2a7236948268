"""Live monitor of a session over a websocket, about 10 updates a second.

Counters, load and the trace ring exist once per session; filter and pause belong to each websocket client (its
view). One feed per session builds each update once per distinct filter among the live clients (the snapshot is
taken once, then filtered per group; the same text goes to every client with that filter), so twenty viewers with
the default filter cost one build. A client that falls behind gets the next update merged with the ones it missed
(trace rows and load points are kept, counters are the newest), so a slow browser never slows the others or the
bus. Rendering on the client is throttled to animation frames.

A new client starts with the session's default view (``PUT /api/.../monitor/filter``, ``POST .../pause``: those
set the defaults for new viewers and the REST snapshot and trace; they do not change the views of connected
clients). ``?rows=N`` asks for up to N trace rows in each hello (200 by default, at most HELLO_TRACE_ROWS_MAX).

Client -> server (JSON text), to change this client's view only:
``{"type": "view", "filter": {"nodes": [...], "services": [...], "cob_min": int, "cob_max": int}?,
   "paused": bool?, "rows": int?}``
The server answers with a ``hello`` (new filter, or resume from a pause: the trace starts again from the ring, so
the rows shown are the newest that pass the new filter), or with ``{"type": "view", "view": {...}}`` (pause: no
more updates until the resume; the page keeps what it shows), or ``{"type": "error", "detail": str}``.

Server -> client (JSON text):

``{"type": "hello" | "update", "seq": int, "server_time": float (epoch s, when built),
   "snapshot": <GET /api/sessions/{id}/monitor without "trace", except "cob_ids" (below); node and COB-ID rows
                as this client's filter shows them; "bus": {"state": "active" | "warning" | "passive" | "bus-off",
                "adapter_state", "tx_errors", "rx_errors", "reported_age_s"}>,
   "history": [[epoch s, load %], ...]   # completed seconds since the previous message (hello: the last 10 min)
   "trace_columns": [...], "trace": [<trace row>, ...],  # decoded telegrams since the previous message that
                                                         # pass this client's filter
   "trace_more": bool,                   # more telegrams came than one message carries (TRACE_PER_UPDATE)
   "recording": {"name", "format", "frames"} | null,
   "view": {"filter": {...}, "paused": bool}}``  # hello only

A reset (``POST .../reset``, shared by all viewers) sends every live client a new hello.

To keep updates small (each is compressed once per client), rows travel as arrays:
``trace`` rows in the order of ``trace_columns``: ``["seq", "time", "cob_id", "service", "group", "node", "dlc",
"hex", "summary"]`` (the REST trace rows are objects and also carry ``text``, ``cob_id service node N: summary``);
``snapshot.cob_ids`` rows in the order of ``snapshot.cob_columns``: ``["text", "service", "node", "total", "rate",
"share_percent", "last_age_s", "ids"]`` (``ids`` > 1: the one row of a scan's requests to node ids that never
answered, ``text`` their range); more than COB_ROWS_PER_UPDATE COB-IDs send the busiest, with ``cob_ids_cut``
the full count.
The socket closes with code 4404 when the session does not exist (or is closed).
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import replace
from typing import Annotated

from fastapi import APIRouter, Query, WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from drivebench.errors import NotFound
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import MonitorView, monitor_for
from drivebench.web.monitor_feed import (  # noqa: F401 (tests and benchmarks read them here)
    HELLO_TRACE_ROWS,
    HELLO_TRACE_ROWS_MAX,
    TRACE_PER_UPDATE,
    Feed,
    FeedClient,
    ViewRequest,
)
from drivebench.web.state import app_state
from drivebench.web.ws.node_socket import serve

router = APIRouter()


def _feed(websocket: WebSocket, session: Session) -> Feed:
    feeds = app_state(websocket.app).monitor_feeds
    feed = feeds.get(session.id)
    if feed is None or feed.session is not session:
        feed = feeds[session.id] = Feed(session, monitor_for(session))
    return feed


async def _receive_views(websocket: WebSocket, feed: Feed, client: FeedClient) -> None:
    """The client's view messages, until it goes away (then it ends quietly)."""
    while True:
        try:
            text = await websocket.receive_text()
        except WebSocketDisconnect:
            return
        try:
            request = ViewRequest.model_validate_json(text)
        except ValidationError as exc:
            answer = {"type": "error", "detail": _problem_text(exc)}
            client.notify(json.dumps(answer))
            continue
        feed.change_view(client, request)


def _problem_text(exc: ValidationError) -> str:
    """``Filter not applied: nodes: Input should be less than or equal to 127`` (the user's words, not pydantic's)."""
    errors = exc.errors(include_url=False)
    if not errors or errors[0]["type"] == "json_invalid" or not errors[0]["loc"]:
        return _("Not a view message: {problem}").format(problem=errors[0]["msg"] if errors else exc)
    problems = []
    for error in errors:
        fields = [str(part) for part in error["loc"][1:] if not isinstance(part, int)]
        message = str(error["msg"]).removeprefix("Value error, ")
        problems.append(f"{', '.join(fields)}: {message}" if fields else message)
    what = {"filter": N_("Filter"), "paused": N_("Pause"), "rows": N_("Trace rows")}.get(str(errors[0]["loc"][0]),
                                                                                         N_("View"))
    return _("{what} not applied: {problems}").format(what=_(what), problems="; ".join(problems))


async def _send_loop(client: FeedClient) -> None:
    while True:
        await client.ready.wait()
        for notice in client.take_notices():
            await client.websocket.send_text(notice)
        if client.pending:
            await client.websocket.send_text(client.take())


@router.websocket("/ws/sessions/{session_id}/monitor")
async def monitor_stream(websocket: WebSocket, session_id: str,
                         rows: Annotated[int, Query(ge=1, le=HELLO_TRACE_ROWS_MAX)] = HELLO_TRACE_ROWS) -> None:
    await websocket.accept()
    try:
        session = app_state(websocket.app).manager.get(session_id)
    except NotFound:
        await websocket.close(code=4404, reason=_("No open session '{session}'").format(session=session_id))
        return
    feed = _feed(websocket, session)
    defaults = feed.monitor.defaults
    view = MonitorView(filter=replace(defaults.filter), paused_at=defaults.paused_at, frozen=defaults.frozen,
                       epoch=defaults.epoch)
    client = FeedClient(websocket, view, rows)
    try:
        hello, _rows = feed.hello(view, rows, client.locale)
        feed.clients.add(client)  # before the first await: updates built from now on queue behind the hello
        if feed.task is None or feed.task.done():
            feed.task = asyncio.create_task(feed.run())
        await websocket.send_text(hello)
        await serve(_receive_views(websocket, feed, client), _send_loop(client))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        feed.clients.discard(client)
