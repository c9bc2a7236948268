"""The queue in front of one SDO channel: one transfer at a time, stop commands before reads.

A device's SDO server answers one transfer at a time, so every transfer on a channel takes the channel's
:class:`ChannelLock` (canopen's blocking client in a worker thread, the expedited reads on the event loop). Waiting
transfers are served in order of arrival, except that *urgent* ones (a quick stop, a disable, the guard's trip) go
before every waiting non-urgent one: the transfer on the wire finishes first, then the stop is the next request the
device sees, however many reads wait (issue 27: 100 viewers' status reads delayed a quick stop by more than a
second). :meth:`ChannelLock.reserved` keeps the channel for a stop that needs more than one transfer (read the
control word, then write it): no waiting read gets in between.
"""

from __future__ import annotations

import contextlib
import threading
from collections import deque
from collections.abc import Iterator
from types import TracebackType


class ChannelLock:
    """A lock with two queues of waiters: urgent ones are handed the lock first, each queue in arrival order.

    Used like ``threading.Lock`` (``with``, ``acquire``/``release``, ``locked``) plus ``urgent=True``."""

    def __init__(self) -> None:
        self._state = threading.Condition(threading.Lock())
        self._held = False
        self._urgent: deque[object] = deque()
        self._normal: deque[object] = deque()
        self._reservations = 0

    def locked(self) -> bool:
        return self._held

    def waiting(self) -> tuple[int, int]:
        """(urgent, other) transfers waiting for the channel."""
        with self._state:
            return len(self._urgent), len(self._normal)

    def _free_for(self, urgent: bool, ticket: object | None) -> bool:
        """May the caller (holding ``ticket`` in its queue, or None when not queued) take the lock now?"""
        if self._held:
            return False
        if urgent:
            return not self._urgent or self._urgent[0] is ticket
        if self._urgent or self._reservations:
            return False
        return not self._normal or self._normal[0] is ticket

    def acquire(self, blocking: bool = True, timeout: float = -1, *, urgent: bool = False) -> bool:
        with self._state:
            if self._free_for(urgent, None):
                self._held = True
                return True
            if not blocking:
                return False
            ticket = object()
            queue = self._urgent if urgent else self._normal
            queue.append(ticket)
            try:
                got = self._state.wait_for(lambda: self._free_for(urgent, ticket),
                                           None if timeout < 0 else timeout)
                if got:
                    self._held = True
                return got
            finally:
                queue.remove(ticket)
                self._state.notify_all()  # the next in line may be another one now

    def release(self) -> None:
        with self._state:
            if not self._held:
                raise RuntimeError("release of an SDO channel that is not held")
            self._held = False
            self._state.notify_all()

    @contextlib.contextmanager
    def held(self, *, urgent: bool = False) -> Iterator[None]:
        self.acquire(urgent=urgent)
        try:
            yield
        finally:
            self.release()

    def __enter__(self) -> bool:
        return self.acquire()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.release()

    @contextlib.contextmanager
    def reserved(self) -> Iterator[None]:
        """Inside, only urgent transfers take the channel: a stop made of several transfers is not interleaved
        with waiting reads (the transfer on the wire when it starts still finishes)."""
        with self._state:
            self._reservations += 1
        try:
            yield
        finally:
            with self._state:
                self._reservations -= 1
                self._state.notify_all()
