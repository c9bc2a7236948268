"""Judging from evidence whether a node a long job is talking to has gone silent.

Two timed-out reads in a row say little on their own: a busy machine answers late, a noisy bus loses a frame.
A node is judged silent only when, after a run of timeouts,

* it does not answer a probe of 0x1000 (device type, mandatory on every CiA 301 device; asked a few times), and
  its heartbeat (the session's heartbeat consumer) is not fresh either; or
* it keeps failing: many timeouts in a row, spread over several seconds, whatever the probe says.

A probe answered for another object every time (the node names the wrong object in every answer) is judged at once:
such a node answers, only never what it is asked. Answered for another object only some of the time, it is a node
answering late (the answer to an earlier request came in while the probe waited): present.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable

from drivebench.errors import SdoAbortError, SdoOutOfStepError, SdoTimeoutError
from drivebench.i18n import N_
from drivebench.protocol.canopen.heartbeat import HeartbeatStatus

SUSPECT_AFTER_TIMEOUTS = 2
"""Timeouts in a row after which the node is probed (and again after every further run of this many)."""
PROBE_ATTEMPTS = 3
"""Probe reads of 0x1000 (each with the session's SDO timeout and retries) before the probe counts as unanswered."""
SILENT_AFTER_TIMEOUTS = 8
SILENT_AFTER_SPAN_S = 5.0
"""This many timeouts in a row, the first and last this far apart: silent even if the node answers probes."""

DID_NOT_ANSWER = N_("did not answer")
OUT_OF_STEP = N_("answered out of step")

Probe = Callable[[], Awaitable[object]]
"""Reads 0x1000 of the node once (raises the SDO errors of a read)."""


class NodeSilence:
    """One node's evidence during one job; shared by the job's SDO channels to that node."""

    def __init__(self, node_id: int, probe: Probe, heartbeat: Callable[[int], HeartbeatStatus]) -> None:
        self.node_id = node_id
        self._probe = probe
        self._heartbeat = heartbeat
        self._timeouts: list[float] = []
        """Monotonic times of the timeouts since the node last answered."""
        self._probe_at = SUSPECT_AFTER_TIMEOUTS
        self._judging = asyncio.Lock()
        self.verdict: str | None = None
        """None while the node counts as present; else why it is given up (``did not answer``, ...)."""

    def answered(self) -> None:
        self._timeouts.clear()
        self._probe_at = SUSPECT_AFTER_TIMEOUTS

    async def timed_out(self, error: SdoTimeoutError | SdoOutOfStepError) -> None:
        """Count a request that got no usable answer; probe the node after a run of them."""
        self._timeouts.append(time.monotonic())
        async with self._judging:  # one probe at a time: the other channel waits for its verdict
            count = len(self._timeouts)
            if self.verdict is not None or count < self._probe_at:
                return
            if count >= SILENT_AFTER_TIMEOUTS and self._timeouts[-1] - self._timeouts[0] >= SILENT_AFTER_SPAN_S:
                self.verdict = OUT_OF_STEP if isinstance(error, SdoOutOfStepError) else DID_NOT_ANSWER
                return
            self._probe_at = count + SUSPECT_AFTER_TIMEOUTS
            answer = await self._probed()
            if answer == OUT_OF_STEP:
                self.verdict = OUT_OF_STEP
            elif answer == DID_NOT_ANSWER and not self._heartbeat_fresh():
                self.verdict = DID_NOT_ANSWER

    async def _probed(self) -> str | None:
        """None when the node answered the probe (an abort is an answer too, and so is a late answer to an earlier
        request), else why not."""
        out_of_step = 0
        for _ in range(PROBE_ATTEMPTS):
            if not self._timeouts:
                return None  # the node answered another request meanwhile
            try:
                await self._probe()
            except SdoAbortError:
                return None
            except SdoOutOfStepError:
                out_of_step += 1
                continue
            except SdoTimeoutError:
                continue
            return None
        if out_of_step == PROBE_ATTEMPTS:
            return OUT_OF_STEP
        return None if out_of_step else DID_NOT_ANSWER

    def _heartbeat_fresh(self) -> bool:
        status = self._heartbeat(self.node_id)
        return status.last_seen is not None and status.expected_period_s() is not None and not status.is_lost()
