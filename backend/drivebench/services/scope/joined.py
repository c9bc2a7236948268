"""Sampling by PDO and polling joined into one source on one time base.

The frames are the PDO part's, one per SYNC (sample n at ``n * period``). The channels of nodes (or objects) that
cannot be sampled by PDO are polled by SDO at their own rate; each poll round is stamped with the newest SYNC sent
when it answered, and each SYNC frame carries the latest round stamped at or before its SYNC (sample and hold; None
until the first poll answered), also when the frame is delivered later (it waited for a late TPDO): a polled
channel changes only every poll round, never between: its real rate is shown beside the PDO rate
(:meth:`JoinedScopeSource.parts`).

Start: the PDO part first (confirmation, node leases, restore record, TPDOs, SYNC), then the polling. Stop: the
polling, then the PDO part, which restores every TPDO and SYNC setting it changed and reads them back.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from drivebench.services.scope.pdo_source import PdoScopeSource, confirmation
from drivebench.services.scope.poll import PollScopeSource
from drivebench.services.scope.source import EventSink, FrameSink, ScopeFrame, SourceKind


def part(kind: SourceKind, nodes: list[int], period_s: float) -> dict[str, Any]:
    """One part of a source as the status shows it: how, which nodes, the rate really reached."""
    return {"kind": kind, "nodes": nodes, "period_s": period_s, "rate": round(1 / period_s, 1) if period_s else None}


class JoinedScopeSource:
    kind: SourceKind = "pdo"

    def __init__(self, pdo: PdoScopeSource, pdo_positions: list[int], poll: PollScopeSource | None,
                 poll_positions: list[int], why_polled: list[str] | None = None) -> None:
        """``pdo_positions[j]``: the recording's channel position of the PDO part's channel j; likewise for the
        polled channels; ``why_polled``: channels polled for reasons the PDO plan does not say, in words."""
        self.pdo = pdo
        self._why_polled = list(why_polled or [])
        self.poll = poll
        self._pdo_positions = pdo_positions
        self._poll_positions = poll_positions
        self._held: list[int | None] = [None] * len(poll_positions)
        self._rounds: deque[tuple[int, list[int | None]]] = deque()
        """Poll rounds not yet in a frame: (the newest SYNC when the round answered, its values)."""
        self._width = len(pdo_positions) + len(poll_positions)
        needed = confirmation(pdo.plan)
        self.moving = [needed] if needed is not None else []

    @property
    def period_s(self) -> float:
        return self.pdo.period_s

    @period_s.setter
    def period_s(self, value: float) -> None:
        self.pdo.period_s = value

    def elapsed_s(self) -> float:
        return self.pdo.elapsed_s()

    def parts(self) -> list[dict[str, Any]]:
        found = [part("pdo", list(self.pdo.plan.pdo_nodes), self.pdo.period_s)]
        if self.poll is not None:
            found.append(part(self.poll.kind, self.poll.nodes, self.poll.period_s))
        return found

    def texts(self) -> list[str]:
        """The plan in words (which TPDO carries what, which nodes are polled and why, the bus share)."""
        return self.pdo.plan.texts() + self._why_polled

    async def start(self, on_frame: FrameSink, on_event: EventSink) -> None:
        def joined(frame: ScopeFrame) -> None:
            while self._rounds and self._rounds[0][0] <= frame.sample:
                self._held = self._rounds.popleft()[1]
            raw: list[int | None] = [None] * self._width
            for position, value in zip(self._pdo_positions, frame.raw, strict=False):
                raw[position] = value
            for position, value in zip(self._poll_positions, self._held, strict=True):
                raw[position] = value
            on_frame(ScopeFrame(frame.sample, frame.time_s, tuple(raw)))

        def polled(frame: ScopeFrame) -> None:
            self._rounds.append((self.pdo.newest_sync(), list(frame.raw)))

        await self.pdo.start(joined, on_event)
        if self.poll is not None:
            try:
                await self.poll.start(polled, on_event)
            except BaseException:
                await self.pdo.stop()
                raise

    async def stop(self) -> list[str]:
        if self.poll is not None:
            await self.poll.stop()
        return await self.pdo.stop()
