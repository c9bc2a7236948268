"""Heartbeat consumer for every node on a bus: NMT state, age, boot-ups and loss detection.

canopen has no heartbeat-loss detection; this listener keeps the last state and time per node and judges a
node lost when no heartbeat came for ``loss_factor`` x its producer period (measured from the telegrams, or
configured from 0x1017).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from drivebench.protocol.canopen.nmt import NmtState

HEARTBEAT_BASE = 0x700


@dataclass
class HeartbeatStatus:
    node_id: int
    state: NmtState | None = None
    last_seen: float | None = None
    period_s: float | None = None
    """Producer period: configured (0x1017) or measured between the last two telegrams."""
    configured_period_s: float | None = None
    bootups: int = 0
    last_bootup: float | None = None
    telegrams: int = 0
    toggle: int | None = None
    """Node guarding toggle bit, when the node answered a guarding request."""
    history: list[tuple[float, str]] = field(default_factory=list)

    def age_s(self, now: float | None = None) -> float | None:
        if self.last_seen is None:
            return None
        return (now or time.time()) - self.last_seen

    def expected_period_s(self) -> float | None:
        return self.configured_period_s or self.period_s

    def is_lost(self, now: float | None = None, loss_factor: float = 2.5) -> bool:
        period, age = self.expected_period_s(), self.age_s(now)
        if period is None or age is None:
            return False
        return age > max(period * loss_factor, period + 0.1)


StateCallback = Callable[[HeartbeatStatus, str], None]


class HeartbeatMonitor(can.Listener):
    """A python-can listener (runs in the notifier thread) for 0x701..0x77F telegrams."""

    HISTORY = 50

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._nodes: dict[int, HeartbeatStatus] = {}
        self._callbacks: list[StateCallback] = []

    def add_callback(self, callback: StateCallback) -> None:
        """``callback(status, event)`` with event ``"bootup"``, ``"state"`` (from the notifier thread)."""
        self._callbacks.append(callback)

    def on_message_received(self, msg: can.Message) -> None:
        node_id = msg.arbitration_id - HEARTBEAT_BASE
        if msg.is_extended_id or msg.is_remote_frame or not 1 <= node_id <= 127 or msg.dlc < 1:
            return
        raw_state = msg.data[0] & 0x7F
        try:
            state = NmtState(raw_state)
        except ValueError:
            return
        now = msg.timestamp or time.time()
        with self._lock:
            status = self._nodes.setdefault(node_id, HeartbeatStatus(node_id))
            event = None
            if state is NmtState.BOOTUP:
                status.bootups += 1
                status.last_bootup = now
                status.period_s = None
                event = "bootup"
                status.history.append((now, "Boot-up"))
            else:
                if status.last_seen is not None and status.state not in (None, NmtState.BOOTUP):
                    interval = now - status.last_seen
                    if interval > 0:
                        previous = status.period_s
                        status.period_s = interval if previous is None else 0.8 * previous + 0.2 * interval
                if state != status.state:
                    event = "state"
                    status.history.append((now, state.label))
            del status.history[: -self.HISTORY]
            status.state = state
            status.last_seen = now
            status.telegrams += 1
        if event:
            for callback in self._callbacks:
                callback(status, event)

    def status(self, node_id: int) -> HeartbeatStatus:
        with self._lock:
            return self._nodes.setdefault(node_id, HeartbeatStatus(node_id))

    def all(self) -> list[HeartbeatStatus]:
        with self._lock:
            return sorted(self._nodes.values(), key=lambda s: s.node_id)

    def set_configured_period(self, node_id: int, period_ms: int) -> None:
        with self._lock:
            status = self._nodes.setdefault(node_id, HeartbeatStatus(node_id))
            status.configured_period_s = period_ms / 1000 if period_ms else None

    def forget(self, node_id: int) -> None:
        with self._lock:
            self._nodes.pop(node_id, None)
