"""The SYNC producer of a PDO recording: a thread that sends SYNC at the period, counts what it sent and measures
the period it really reaches.

The count is taken under a lock around each send, and a TPDO frame is stamped under the same lock
(:meth:`SyncProducer.stamp`): a frame received while a SYNC is being sent waits for it, so it is stamped with the
SYNC it answers. Each SYNC's send time is kept in ``time.time()``'s clock (taken just before the send), so that a
frame the bus stamped can be put at the last SYNC sent before it was on the bus (:meth:`SyncProducer.stamp_at`),
also when the thread that receives it was behind. A producer thread that falls behind by several periods (a loaded
machine) does not burst to catch up: it restarts its clock and reports the pause.
"""

from __future__ import annotations

import threading
import time
from array import array
from bisect import bisect_right
from collections.abc import Callable

from drivebench.errors import DriveBenchError

PAUSE_PERIODS = 5
PAUSE_MIN_S = 0.02
"""A gap of this many periods (and at least this long) between two SYNCs is reported as a pause."""
KEPT_SEND_TIMES = 65_536
"""Send times kept for :meth:`SyncProducer.stamp_at` (at least this many, the newest; 65 s at a 1 ms period, where a
sample waits 1 s): a recording that runs for hours keeps 0.5-1 MB, not 8 bytes per SYNC it ever sent."""


class SyncProducer:
    def __init__(self, send: Callable[[], None], period_s: float) -> None:
        self._send = send
        self.nominal_s = period_s
        self.count = 0
        """SYNCs sent; the newest has the number ``count - 1``."""
        self.first: float | None = None
        self.last: float | None = None
        self.error: str | None = None
        self.pauses: list[tuple[int, float]] = []
        """(SYNC number, seconds) of each pause (:data:`PAUSE_PERIODS`, :data:`PAUSE_MIN_S`)."""
        self._sent_at = array("d")
        """``time.time()`` just before each SYNC's send, from SYNC number :attr:`_sent_from` on."""
        self._sent_from = 0
        self._pause_s = max(PAUSE_PERIODS * period_s, PAUSE_MIN_S)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scope-sync", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)

    def stamp(self) -> int:
        """The number of the newest SYNC sent (-1 before the first)."""
        with self._lock:
            return self.count - 1

    def stamp_at(self, timestamp: float, received: float) -> int | None:
        """The number of the last SYNC sent at or before ``timestamp`` (a frame's bus timestamp), None where that
        timestamp is not plausible in ``time.time()``'s clock (``received``: when the frame was taken): later than
        its receive, or before the oldest SYNC kept (an adapter or gateway with a clock of its own, or no timestamp;
        :data:`KEPT_SEND_TIMES`)."""
        with self._lock:
            if not self._sent_at or not self._sent_at[0] <= timestamp <= received:
                return None
            return self._sent_from + bisect_right(self._sent_at, timestamp) - 1

    @property
    def period_s(self) -> float:
        """The mean period reached so far (the nominal one before two SYNCs went out)."""
        if self.first is None or self.last is None or self.count < 2:
            return self.nominal_s
        return (self.last - self.first) / (self.count - 1)

    def _run(self) -> None:
        next_at = time.monotonic()
        while not self._stop.is_set():
            with self._lock:
                sent_at = time.time()
                try:
                    self._send()
                except DriveBenchError as exc:
                    self.error = exc.detail  # a Text: the SYNC lost marker is shown in each reader's language
                    return
                now = time.monotonic()
                if self.last is not None and now - self.last > self._pause_s:
                    self.pauses.append((self.count, now - self.last))
                self.first = now if self.first is None else self.first
                self.last = now
                self._sent_at.append(sent_at)
                if len(self._sent_at) >= 2 * KEPT_SEND_TIMES:
                    del self._sent_at[:KEPT_SEND_TIMES]
                    self._sent_from += KEPT_SEND_TIMES
                self.count += 1
            next_at += self.nominal_s
            delay = next_at - time.monotonic()
            if delay < -PAUSE_PERIODS * self.nominal_s:
                next_at = time.monotonic()  # far behind: no burst of SYNCs to catch up
            elif delay > 0:
                self._stop.wait(delay)
