"""NMT master side of CiA 301 node guarding: a remote frame on 0x700+id every guard time, the node answers with
its state and a toggle bit that alternates; no valid answer within guard time x life time factor is a loss.

canopen's ``NmtMaster.start_node_guarding`` only sends the remote frames; detecting the loss and the toggle
errors is done here.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import can

from drivebench.protocol.canopen.nmt import NmtState

GUARD_BASE = 0x700
TICK_S = 0.01


@dataclass
class GuardStatus:
    node_id: int
    guard_time_s: float
    life_time_factor: int
    started: float
    next_request: float = 0.0
    last_answer: float | None = None
    state: NmtState | None = None
    expected_toggle: int | None = None
    toggle_errors: int = 0
    requests: int = 0
    answers: int = 0
    awaiting: bool = False
    """A remote frame was sent and not answered yet: only then is a 0x700+id frame a guarding answer."""

    @property
    def life_time_s(self) -> float:
        return self.guard_time_s * max(self.life_time_factor, 1)

    def is_lost(self, now: float | None = None) -> bool:
        """No answer for the node life time (from the first request when the node never answered)."""
        reference = self.last_answer if self.last_answer is not None else self.started
        return (now or time.time()) - reference > self.life_time_s + self.guard_time_s


class NodeGuarding(can.Listener):
    """Guards any number of nodes from one timer thread; answers arrive through the network's notifier."""

    def __init__(self, send: Callable[[can.Message], None]) -> None:
        self._send = send
        self._lock = threading.Lock()
        self._guards: dict[int, GuardStatus] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, node_id: int, guard_time_ms: int, life_time_factor: int) -> GuardStatus:
        now = time.time()
        status = GuardStatus(node_id, guard_time_ms / 1000, life_time_factor, started=now, next_request=now)
        with self._lock:
            self._guards[node_id] = status
            if self._thread is None:
                self._stop.clear()
                self._thread = threading.Thread(target=self._run, name="node-guarding", daemon=True)
                self._thread.start()
        return status

    def release(self, node_id: int) -> None:
        with self._lock:
            self._guards.pop(node_id, None)

    def status(self, node_id: int) -> GuardStatus | None:
        with self._lock:
            return self._guards.get(node_id)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1)
            self._thread = None

    def on_message_received(self, msg: can.Message) -> None:
        node_id = msg.arbitration_id - GUARD_BASE
        if msg.is_remote_frame or msg.is_extended_id or msg.dlc < 1 or not 1 <= node_id <= 127:
            return
        with self._lock:
            status = self._guards.get(node_id)
            if status is None or not status.awaiting:
                return
            status.awaiting = False
            toggle = msg.data[0] >> 7
            if status.expected_toggle is not None and toggle != status.expected_toggle:
                status.toggle_errors += 1
            status.expected_toggle = toggle ^ 1
            try:
                status.state = NmtState(msg.data[0] & 0x7F)
            except ValueError:
                status.state = None
            status.last_answer = msg.timestamp or time.time()
            status.answers += 1

    def _run(self) -> None:
        while not self._stop.wait(TICK_S):
            now = time.time()
            with self._lock:
                due = [s for s in self._guards.values() if now >= s.next_request]
                for status in due:
                    status.next_request = now + status.guard_time_s
                    status.requests += 1
                    status.awaiting = True
            for status in due:
                # A send error is reported by the adapter itself; the node then counts as lost.
                with contextlib.suppress(can.CanError):
                    self._send(can.Message(arbitration_id=GUARD_BASE + status.node_id, is_remote_frame=True,
                                           dlc=1, is_extended_id=False))
