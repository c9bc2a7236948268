"""The CAN controller's fault confinement state (ISO 11898-1): error active, warning, error passive, bus-off.

Two sources, the worse one wins:
- the adapter's own report (python-can ``BusABC.state``: ACTIVE, PASSIVE, ERROR = bus-off), where it has one;
- error frames in the SocketCAN encoding (``linux/can/error.h``), which python-can passes through unchanged for
  socketcan and which socketcand gateways forward: the error class in the identifier, the controller status in
  ``data[1]``, the transmit and receive error counters in ``data[6]`` and ``data[7]`` (filled by the kernel's
  ``can_change_state`` and with ``CAN_ERR_CNT``). Other adapters' error frames carry no counters here.

Without counters from the controller the state is the last one reported; the kernel reports the way back to error
active (``CAN_ERR_CRTL_ACTIVE``, ``CAN_ERR_RESTARTED``), so it does not stick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import can

STATES = ("active", "warning", "passive", "bus-off")
"""Ordered from good to bad."""

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
