"""One status poll per node, shared by every control panel that watches it (issue 27 item 7).

A hundred viewers of a node's Control tab used to poll its status word, control word, mode and actual values a
hundred times over: the bus carried more than a thousand SDO frames a second and a quick stop queued behind them.
Now the first panel that watches a node starts its :class:`NodePoll`, which reads the node every
:data:`PERIOD_S` and hands the result to every watching panel; the last one leaving stops it. Each value is read
from the bus once per period whatever the number of watchers and languages among them (the status is worded per
language, from the same reads: :func:`reads.snapshot`). A panel that cannot keep up gets the newest status
only; it never slows the poll or the other panels.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
import weakref
from collections.abc import AsyncIterator
from typing import Any

from drivebench.errors import DriveBenchError
from drivebench.i18n import current, using
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control import drive_control
from drivebench.services.params import reads

PERIOD_S = 0.25
log = logging.getLogger(__name__)
Message = dict[str, Any]


class Watcher:
    """One panel's place at a node's poll: the newest message for it (older ones it did not take are dropped)."""

    def __init__(self, locale: str) -> None:
        self.locale = locale
        self._message: Message | None = None
        self._ready = asyncio.Event()

    def offer(self, message: Message) -> None:
        self._message = message
        self._ready.set()

    async def next(self) -> Message:
        """The newest status (or error) message since the last call; waits for the next poll if none."""
        await self._ready.wait()
        self._ready.clear()
        message, self._message = self._message, None
        assert message is not None
        return message


class NodePoll:
    """The node's status read once per period for all its watchers."""

    def __init__(self, session: Session, node: SessionNode) -> None:
        self.session = session
        self.node = node
        self.watchers: set[Watcher] = set()
        self.task: asyncio.Task[None] | None = None

    async def _run(self) -> None:
        while self.watchers:
            try:
                await self.poll_once()
            except Exception:  # a bug must not leave every panel of the node without a status for good
                log.exception("status poll of node %s failed", self.node.node_id)
            await asyncio.sleep(PERIOD_S)

    async def poll_once(self) -> None:
        """Read the node once and offer every watcher the status in its language."""
        by_locale: dict[str, list[Watcher]] = {}
        for watcher in list(self.watchers):
            by_locale.setdefault(watcher.locale, []).append(watcher)
        with reads.snapshot():
            for locale, watchers in sorted(by_locale.items()):
                with using(locale):
                    message = await self._message()
                for watcher in watchers:
                    watcher.offer(message)

    async def _message(self) -> Message:
        try:
            status = await drive_control.read_status(self.session, self.node)
            actuals = await drive_control.read_actuals(self.session, self.node)
        except DriveBenchError as exc:
            return {"type": "error", "detail": exc.shown_detail()}
        return {"type": "status", "status": status.model_dump(mode="json"),
                "actuals": [a.model_dump(mode="json") for a in actuals], "t": time.time()}


_POLLS: weakref.WeakKeyDictionary[Session, dict[int, NodePoll]] = weakref.WeakKeyDictionary()


@contextlib.asynccontextmanager
async def watching(session: Session, node: SessionNode) -> AsyncIterator[Watcher]:
    """Inside, the node's shared poll runs and offers this watcher (in the caller's language) each status; the
    poll starts with its first watcher and stops with its last."""
    polls = _POLLS.setdefault(session, {})
    poll = polls.get(node.node_id)
    if poll is None:
        poll = polls[node.node_id] = NodePoll(session, node)
    watcher = Watcher(current())
    poll.watchers.add(watcher)
    if poll.task is None or poll.task.done():
        poll.task = asyncio.get_running_loop().create_task(poll._run())
    try:
        yield watcher
    finally:
        poll.watchers.discard(watcher)
        if not poll.watchers:
            if polls.get(node.node_id) is poll:
                del polls[node.node_id]
            if poll.task is not None:
                poll.task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await poll.task
