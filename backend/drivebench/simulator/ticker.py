"""The thread that runs simulated devices' timed work (heartbeats, a drive's cycle while it moves, TPDO timers) at
the deadlines they name, and sleeps in between: an idle plant costs next to nothing (issue 21)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from typing import Protocol

MIN_SLEEP_S = 0.001
MAX_SLEEP_S = 1.0
"""The ticker sleeps until the earliest deadline a device names or until a device wakes it (a frame or a write
changed something); never longer than this (a change made without telling the device, e.g. a value set with
``notify=False``, is taken up within this time)."""


class Ticking(Protocol):
    def tick(self, now: float) -> float | None:
        """Do what is due at ``now``; the ``time.monotonic()`` of the next deadline, or None until woken."""


class DeadlineTicker:
    def __init__(self, devices: Callable[[], Iterable[Ticking]], name: str) -> None:
        self._devices = devices
        self._name = name
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2)

    def wake(self) -> None:
        """Something changed (any thread): tick now rather than at the next deadline. The ticker's own changes
        need no wake-up: it asks every device for its next deadline after ticking."""
        if threading.current_thread() is not self._thread:
            self._wake.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.clear()
            now = time.monotonic()
            due = [at for device in self._devices() if (at := device.tick(now)) is not None]
            sleep = min(due) - time.monotonic() if due else MAX_SLEEP_S
            self._wake.wait(min(max(sleep, MIN_SLEEP_S), MAX_SLEEP_S))
