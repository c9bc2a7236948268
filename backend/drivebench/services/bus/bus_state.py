"""The CAN controller's fault confinement state (ISO 11898-1): error active, warning, error passive, bus-off.

Two sources, the worse one wins:
- the adapter's own report (python-can ``BusABC.state``: ACTIVE, PASSIVE, ERROR = bus-off), where it has one;
- error frames in the SocketCAN encoding (``linux/can/error.h``), which python-can passes through unchanged for
  socketcan and which socketcand gateways forward: the error class in the identifier, the controller status in
  ``data[1]``, the transmit and receive error counters in ``data[6]`` and ``data[7]`` (filled by the kernel's
  ``can_change_state`` and with ``CAN_ERR_CNT``). Other adapters' error frames carry no counters here.

Without counters from the controller the state is the last one reported; the kernel reports the way back to error
active (``CAN_ERR_CRTL_ACTIVE``, ``CAN_ERR_RESTARTED``), so it does not stick.

:class:`BusHealth` is a session's view of its bus: that state, plus whether the adapter works at all (the
transport's link: ``adapter lost`` while it reconnects), in words for the Plant page, the monitor and the API.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from drivebench.i18n import N_, Text, _, shown
from drivebench.protocol.ethercat.network import EthercatNetwork
from drivebench.transport.bus import LinkState, ObservedBus

STATES = ("active", "warning", "passive", "bus-off")
"""Ordered from good to bad."""
ADAPTER_LOST = "adapter lost"
"""Not a controller state: the adapter itself does not work (``BusHealth.state``)."""

CAN_ERR_CRTL = 0x004
CAN_ERR_BUSOFF = 0x040
CAN_ERR_RESTARTED = 0x100
CAN_ERR_CNT = 0x200
CRTL_WARNING = 0x04 | 0x08  # RX / TX warning
CRTL_PASSIVE = 0x10 | 0x20  # RX / TX passive
CRTL_ACTIVE = 0x40
WARNING_LIMIT = 96
PASSIVE_LIMIT = 128
ADAPTER_STATES = {"active": "active", "passive": "passive", "error": "bus-off"}
"""python-can's BusState names -> ours."""


def worse(first: str, second: str) -> str:
    return first if STATES.index(first) >= STATES.index(second) else second


def state_from_counters(tx_errors: int, rx_errors: int) -> str:
    """ISO 11898-1: warning at 96, error passive at 128 (bus-off needs the error frame's flag: TEC > 255)."""
    highest = max(tx_errors, rx_errors)
    if highest >= PASSIVE_LIMIT:
        return "passive"
    if highest >= WARNING_LIMIT:
        return "warning"
    return "active"


@dataclass
class BusErrorState:
    """What the error frames said last (updated on the listener thread, read by snapshots)."""

    state: str | None = None
    tx_errors: int | None = None
    rx_errors: int | None = None
    reported_at: float | None = None

    def observe(self, msg: can.Message, now: float) -> None:
        error_class = msg.arbitration_id
        data = bytes(msg.data)
        state: str | None = None
        if error_class & (CAN_ERR_CRTL | CAN_ERR_CNT) and len(data) >= 8:
            self.tx_errors, self.rx_errors = data[6], data[7]
            state = state_from_counters(data[6], data[7])
        if error_class & CAN_ERR_CRTL and len(data) >= 2:
            status = data[1]
            if status & CRTL_PASSIVE:
                state = "passive"
            elif status & CRTL_WARNING:
                state = worse(state or "active", "warning")
            elif status & CRTL_ACTIVE:
                state = "active"
        if error_class & CAN_ERR_RESTARTED:
            state = "active"
        if error_class & CAN_ERR_BUSOFF:  # TEC went past 255; the frame carries no counters
            state = "bus-off"
            self.tx_errors = self.rx_errors = None
        if state is not None:
            self.state = state
            self.reported_at = now

    def as_dict(self, adapter_state: str, now: float) -> dict[str, Any]:
        adapter = ADAPTER_STATES.get(adapter_state, "active")
        return {"state": worse(adapter, self.state or "active"), "adapter_state": adapter,
                "tx_errors": self.tx_errors, "rx_errors": self.rx_errors,
                "reported_age_s": round(now - self.reported_at, 1) if self.reported_at is not None else None}


def _clock(wall: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(wall)) if wall else "?"


BusEvent = Callable[[str, dict[str, object]], None]


class BusHealth(can.Listener):
    """A session's bus in one word and one sentence: the adapter's link, then its controller's state.

    Reads the error frames (listener), the adapter's own report (``bus.state``) and the link; a change of the
    state is written to ``changes`` (newest last) and told to ``on_change`` when someone next looks (sends,
    page, API, monitor), so no thread polls.
    """

    def __init__(self, bus: ObservedBus, on_change: BusEvent | None = None) -> None:
        self.bus = bus
        self.on_change = on_change
        self.errors = BusErrorState()
        self.changes: deque[tuple[float, str, str]] = deque(maxlen=20)
        """(wall time, from, to)"""
        self._lock = threading.Lock()
        self._last = "active"
        self.notes: list[Callable[[], str | None]] = []
        """More sentences about the bus (the monitor's babbling-node finding), added to :meth:`text`."""
        bus.watch_link(self._on_link)

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            with self._lock:
                self.errors.observe(msg, time.monotonic())

    def _on_link(self, link: LinkState) -> None:
        self.state()

    def adapter_state(self) -> str:
        try:
            return ADAPTER_STATES.get(self.bus.state.name.lower(), "active")
        except Exception:  # a closed or unplugged adapter: its own report is unknown
            return "active"

    def state(self) -> str:
        """``active``, ``warning``, ``passive``, ``bus-off`` or ``adapter lost``."""
        if self.bus.link.lost:
            current = ADAPTER_LOST
        else:
            with self._lock:
                reported = self.errors.state or "active"
            current = worse(self.adapter_state(), reported)
        with self._lock:
            previous, self._last = self._last, current
            if current != previous:
                self.changes.append((time.time(), previous, current))
        if current != previous and self.on_change is not None:
            self.on_change("bus_state", {"from": previous, "to": current})
        return current

    def refusal(self) -> str | None:
        """Why nothing may be sent now (bus-off), or None (the ObservedBus send guard)."""
        if self.state() == "bus-off":
            return _("bus-off: the CAN controller has left the bus after too many transmit errors; nothing is sent "
                     "until it recovers")
        return None

    def text(self) -> str | None:
        """The state in a sentence, plus the notes, in the current language; None while all is well and has been
        since the session opened."""
        sentences = [shown(self.state_text() or ""), *(note() for note in list(self.notes))]
        return " ".join(sentence for sentence in sentences if sentence) or None

    def state_text(self) -> Text | None:
        """The state alone in a sentence (no notes), worded when shown: one snapshot serves readers of any
        language."""
        state = self.state()
        link = self.bus.link
        with self._lock:
            tx, rx = self.errors.tx_errors, self.errors.rx_errors
        counters = f" (TEC {tx}, REC {rx})" if tx is not None else ""
        if state == ADAPTER_LOST:
            lost = Text(N_("adapter lost: {reason} since {clock}"), reason=link.lost_reason,
                        clock=_clock(link.lost_at))
            reconnecting = (Text(N_("reconnecting, {count} attempts so far"), count=link.attempts) if link.attempts
                            else Text(N_("reconnecting")))
            text = Text.joined("; ", [lost, reconnecting])
            if link.last_attempt_error:
                text = Text.joined(" ", [text, Text(N_("(last: {error})"), error=link.last_attempt_error)])
            return text
        if state == "bus-off":
            return Text(N_("bus-off: the CAN controller left the bus after too many transmit errors; requests fail "
                           "at once until it recovers. Check wiring, termination and that every node has the same "
                           "bit rate."))
        if state == "passive":
            return Text(N_("error passive{counters}: the controller sees many bus errors and only sends passive "
                           "error flags. Check wiring, termination and bit rate."), counters=counters)
        if state == "warning":
            return Text(N_("error warning{counters}: the error counters passed 96; the bus has frequent errors."),
                        counters=counters)
        if self.changes:
            at, previous, _current = self.changes[-1]
            if previous == ADAPTER_LOST:
                return Text(N_("adapter back at {clock} (reconnected {count}x); error active"), clock=_clock(at),
                            count=link.reconnects)
            return Text(N_("recovered from {state} at {clock}: error active"), state=previous, clock=_clock(at))
        return None

    def as_dict(self, now: float | None = None) -> dict[str, Any]:
        """For the monitor: the state, its sentence, the counters, the adapter's own report and the link."""
        with self._lock:
            data = self.errors.as_dict(self.adapter_state(), time.monotonic() if now is None else now)
        link = self.bus.link
        data.update(state=self.state(), adapter_state=self.adapter_state(), text=self.state_text(),
                    link={"lost": link.lost, "reason": link.lost_reason, "since": link.lost_at,
                          "attempts": link.attempts, "reconnects": link.reconnects})
        return data


class GatewayHealth:
    """An EtherCAT session's link to its mailbox gateway in one word and one sentence: it has no CAN controller, so
    only ``active`` or ``adapter lost`` (nothing listens on the gateway's port)."""

    def __init__(self, network: EthercatNetwork) -> None:
        self.network = network
        self.notes: list[Callable[[], str | None]] = []

    def state(self) -> str:
        return ADAPTER_LOST if self.network.link_text else "active"

    def refusal(self) -> str | None:
        return None

    def text(self) -> str | None:
        sentences = [shown(self.network.link_text or ""), *(note() for note in self.notes)]
        return " ".join(s for s in sentences if s) or None

    def state_text(self) -> Text | None:
        return self.network.link_text

    def as_dict(self, now: float | None = None) -> dict[str, Any]:
        return {"state": self.state(), "adapter_state": self.state(), "tx_errors": None, "rx_errors": None,
                "reported_age_s": None, "text": self.state_text(),
                "link": {"lost": bool(self.network.link_text), "reason": self.network.link_text, "since": None,
                         "attempts": 0, "reconnects": 0}}
