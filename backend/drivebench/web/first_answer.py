"""What a server start puts off until it has answered its first request (issue 33: /api/health within 2 s of a
restart): reading a large folder of stored uploads and building FastAPI's route copies are work of worker threads
that took their share of the CPU (the GIL) while the first answer was made; they begin once it is sent."""

from __future__ import annotations

import asyncio
import contextlib
import inspect
from collections.abc import Awaitable, Callable

from starlette.types import ASGIApp, Receive, Scope, Send


class AnswerSignal:
    """Set once the running app has answered an HTTP request; each start (lifespan) arms a new one."""

    def __init__(self) -> None:
        self.answered: asyncio.Event | None = None

    def arm(self) -> asyncio.Event:
        self.answered = asyncio.Event()
        return self.answered


class FirstAnswer:
    """ASGI middleware: sets the app's :class:`AnswerSignal` when its first HTTP answer has been sent."""

    def __init__(self, app: ASGIApp, *, signal: AnswerSignal) -> None:
        self.app, self.signal = app, signal

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        answered = self.signal.answered
        if scope["type"] != "http" or answered is None or answered.is_set():
            await self.app(scope, receive, send)
            return
        try:
            await self.app(scope, receive, send)
        finally:
            answered.set()


def after_answer(answered: asyncio.Event, work: Callable[[], Awaitable[object] | None]) -> asyncio.Task[None]:
    """``work`` once ``answered`` is set (a task: :func:`end` stops it if the server stops before)."""

    async def then() -> None:
        await answered.wait()
        result = work()
        if inspect.isawaitable(result):
            await result

    return asyncio.create_task(then())


async def end(task: asyncio.Task[None], answered: asyncio.Event) -> None:
    """At shutdown: what never began is cancelled, what began is waited for."""
    if not answered.is_set():
        task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
