"""Every open websocket re-checks its user each second, as a request is checked each time (issue 27 item 6).

A socket is admitted at its handshake (``access.admitted``); from then on, every :data:`RECHECK_PERIOD_S`,
``access.still_admitted`` asks again (the database state: the cookie session or API token, the user's role, the
share link). When the answer changes - the user disabled, given a lower role or a new password, signed out, the
token or link revoked - the socket is closed with 4401 (no longer signed in) or 4403 (not allowed), its reason in
words, and the nodes its panel held (``web/safety.panel_for``) are stopped at once (``Guard.trip``: quick stop), not
only at their keep-alive deadline. The route then sees its client go away (``websocket.disconnect`` with that
code) and ends as it does when a browser leaves; whatever it sends afterwards is dropped.

A change of accounts made through this app (a user disabled, given a lower role or a new password, a token
revoked, a sign-out: ``web/api/accounts.py``, the Users page) does not wait for the next period: the route calls
:func:`recheck_now` before it answers, so her drives are stopped because her access ended, at once, and never
later by a keep-alive deadline that a busy server let pass first.

This runs around every websocket route in one place (``web/gate.py``): a new socket needs nothing of its own.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from starlette.applications import Starlette
from starlette.requests import HTTPConnection
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from starlette.websockets import WebSocketDisconnect

from drivebench.errors import DriveBenchError, NotAuthenticated, NotFound
from drivebench.i18n import N_, Text
from drivebench.services.control import drive_control
from drivebench.web.safety import panel_for
from drivebench.web.state import app_state

RECHECK_PERIOD_S = 1.0
CLOSE_WAIT_S = 5.0
LOST_REASON = N_("the user of the live connection holding it may no longer hold it (access ended)")
log = logging.getLogger(__name__)
_trips: set[asyncio.Task[None]] = set()

Recheck = Callable[[], Awaitable[DriveBenchError | None]]


class LiveSocket:
    """One websocket's ASGI ``receive`` and ``send`` as the route sees them, and its re-check."""

    def __init__(self, scope: Scope, receive: Receive, send: Send, recheck: Recheck) -> None:
        self.scope, self._receive, self._send, self._recheck = scope, receive, send, recheck
        self.accepted = asyncio.Event()
        self.lost = asyncio.Event()
        self.code = 1000
        self._closed = False
        self._sending = asyncio.Lock()
        self._checking = asyncio.Lock()
        self._next: asyncio.Future[Message] | None = None
        self.stops: list[asyncio.Task[None]] = []
        """The quick stops of the nodes it held, once it was closed for lost access."""

    async def receive(self) -> Message:
        if self._next is None and not self.lost.is_set():
            self._next = asyncio.ensure_future(self._receive())
        if self._next is not None and not self.lost.is_set():
            lost: asyncio.Future[Any] = asyncio.ensure_future(self.lost.wait())
            waiting: set[asyncio.Future[Any]] = {self._next, lost}
            try:
                await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
            finally:
                lost.cancel()
            if self._next.done():  # a message that came first is handed on (a close of the client's own too)
                message, self._next = self._next.result(), None
                return message
        return {"type": "websocket.disconnect", "code": self.code}

    async def send(self, message: Message) -> None:
        async with self._sending:
            if self.lost.is_set():
                if message["type"] == "websocket.close":
                    return
                raise WebSocketDisconnect(self.code)
            if message["type"] == "websocket.close":
                self._closed = True
            await self._send(message)
        if message["type"] == "websocket.accept":
            self.accepted.set()

    async def watch(self) -> None:
        await self.accepted.wait()
        while True:
            await asyncio.sleep(RECHECK_PERIOD_S)
            if await self.recheck():
                return

    async def recheck(self) -> bool:
        """Ask again whether the socket may stay open; close it when not. True once it is closed."""
        async with self._checking:  # the period's re-check and one after an account change: one at a time
            if self.lost.is_set():
                return True
            try:
                refused = await self._recheck()
            except Exception:  # the database away for a moment: the next re-check asks again
                log.exception("re-check of a live connection failed")
                return False
            if refused is None:
                return False
            await self._close(refused)
            return True

    async def _close(self, refused: DriveBenchError) -> None:
        self.code = 4401 if isinstance(refused, NotAuthenticated) else 4403
        self.stops = _stop_what_it_held(self.scope)
        async with self._sending:
            self.lost.set()  # from here on the route's sends are dropped and its receive hears the close
            if not self._closed:
                self._closed = True
                with contextlib.suppress(Exception):  # the client may be gone already
                    await self._send({"type": "websocket.close", "code": self.code,
                                      "reason": refused.shown_detail()[:120]})

    def cancel(self) -> None:
        if self._next is not None:
            self._next.cancel()


def _stop_what_it_held(scope: Scope) -> list[asyncio.Task[None]]:
    """Quick stop, at once, for the nodes the socket's panel holds in its session (none for a socket outside one)."""
    session_id = scope.get("path_params", {}).get("session_id")
    if session_id is None:
        return []
    try:
        session = scope["app"].state.drivebench.manager.get(session_id)
    except NotFound:
        return []
    guard = drive_control.guard_for(session)
    stops = []
    for node_id in guard.held_by(panel_for(HTTPConnection(scope))):
        trip = asyncio.get_running_loop().create_task(guard.trip(node_id, Text(LOST_REASON)))
        _trips.add(trip)  # kept until done: the stop completes whatever happens to the socket
        trip.add_done_callback(_trips.discard)
        stops.append(trip)
    return stops


async def recheck_now(app: Starlette) -> None:
    """Re-check every open websocket of ``app`` at once (an account changed through it) and return when those no
    longer admitted are closed and the nodes they held are stopped (the quick stops waited for at most
    ``CLOSE_WAIT_S``; they complete anyway)."""
    live: set[LiveSocket] = app_state(app).live_sockets
    sockets = [socket for socket in live if socket.accepted.is_set()]
    # shielded: a re-check that closes a socket runs to its end even when the admin's request goes away
    closed = await asyncio.gather(*(asyncio.shield(socket.recheck()) for socket in sockets))
    stops = [stop for socket, lost in zip(sockets, closed, strict=True) if lost for stop in socket.stops]
    if stops:
        await asyncio.wait(stops, timeout=CLOSE_WAIT_S)


async def serve(app: ASGIApp, scope: Scope, receive: Receive, send: Send, recheck: Recheck) -> None:
    """Run the websocket route ``app`` with ``recheck`` asked every second while the socket is open."""
    socket = LiveSocket(scope, receive, send, recheck)
    watch = asyncio.create_task(socket.watch())
    live: set[LiveSocket] = app_state(scope["app"]).live_sockets
    live.add(socket)
    try:
        await app(scope, socket.receive, socket.send)
    finally:
        live.discard(socket)
        if socket.lost.is_set():  # the route ended because the re-check closed it: the close goes out first
            await asyncio.wait({watch}, timeout=CLOSE_WAIT_S)
        watch.cancel()
        socket.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await watch
