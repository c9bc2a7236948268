"""The fallback source: every channel read by SDO (CAN) or CoE (EtherCAT) once per round, through the parameters
read path (one batch per node, on the event loop), a round every ``period_s`` at most.

A round takes as long as its reads: ``period_s`` becomes the period really reached (the time since the start over
the rounds since), which the page shows as the rate. A node that does not answer gives ``None`` for its channels
in that round and one event in words (again only once it answered in between).
"""

from __future__ import annotations

import asyncio
import contextlib
import time

from drivebench.errors import DriveBenchError
from drivebench.i18n import N_, Text
from drivebench.services.bus.sessions import Session
from drivebench.services.params import reads
from drivebench.services.scope.source import EventSink, FrameSink, ScopeChannel, ScopeEvent, ScopeFrame, SourceKind


class PollScopeSource:
    def __init__(self, session: Session, channels: list[ScopeChannel], period_s: float,
                 why: list[str] | None = None) -> None:
        self.session = session
        self._why = list(why or [])
        self.channels = channels
        self.asked_period_s = period_s
        self.period_s = period_s
        self.kind: SourceKind = "sdo-poll" if session.network.capabilities.frames else "coe-poll"
        self._task: asyncio.Task[None] | None = None
        self._started: float | None = None
        self._by_node: dict[int, list[str]] = {}
        for channel in channels:
            refs = self._by_node.setdefault(channel.node, [])
            if channel.ref not in refs:
                refs.append(channel.ref)

    @property
    def nodes(self) -> list[int]:
        return sorted(self._by_node)

    def texts(self) -> list[str]:
        """Why the channels are polled, in words (the plan's reasons for each node)."""
        return list(self._why)

    async def start(self, on_frame: FrameSink, on_event: EventSink) -> None:
        self._task = asyncio.create_task(self._run(on_frame, on_event))

    async def stop(self) -> list[str]:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        return []  # polling changes nothing on the nodes

    async def _round(self, silent: set[int], started: float, on_event: EventSink) -> tuple[int | None, ...]:
        raws: dict[tuple[int, str], int | None] = {}
        for node_id, refs in self._by_node.items():
            try:
                answers: list[object] = list(await reads.read_many(self.session, node_id, refs))
            except DriveBenchError as exc:
                answers = [exc] * len(refs)
            failed = next((a for a in answers if isinstance(a, DriveBenchError)), None)
            if failed is not None and node_id not in silent:
                silent.add(node_id)
                on_event(ScopeEvent(time.monotonic() - started, node_id, "source", Text(
                    N_("Node {node} did not answer the poll: {error}"), node=node_id, error=failed.detail)))
            elif failed is None:
                silent.discard(node_id)
            for ref, answer in zip(refs, answers, strict=True):
                raw = getattr(answer, "raw", None)
                raws[(node_id, ref)] = raw if isinstance(raw, int) else None
        return tuple(raws.get((c.node, c.ref)) for c in self.channels)

    def elapsed_s(self) -> float:
        return 0.0 if self._started is None else time.monotonic() - self._started

    async def _run(self, on_frame: FrameSink, on_event: EventSink) -> None:
        started = self._started = time.monotonic()
        silent: set[int] = set()
        rounds = 0
        while True:
            due = started + rounds * self.asked_period_s
            at = time.monotonic()
            raw = await self._round(silent, started, on_event)
            on_frame(ScopeFrame(rounds, at - started, raw))
            if rounds:  # round n starts no earlier than n periods after the first: never faster than asked
                self.period_s = (at - started) / rounds
            rounds += 1
            await asyncio.sleep(max(0.0, due + self.asked_period_s - time.monotonic()))
