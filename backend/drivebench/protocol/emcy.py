"""Emergency telegrams (CiA 301): received, decoded to code, class, error register bits; history per node."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import can

EMCY_BASE = 0x80

# CiA 301 emergency error code classes (high byte; 0x10 .. 0xFF).
ERROR_CODE_CLASSES = [
    (0x0000, 0x00FF, "Error reset or no error"),
    (0x1000, 0x10FF, "Generic error"),
    (0x2000, 0x20FF, "Current"),
    (0x2100, 0x21FF, "Current, device input side"),
    (0x2200, 0x22FF, "Current inside the device"),
    (0x2300, 0x23FF, "Current, device output side"),
    (0x3000, 0x30FF, "Voltage"),
    (0x3100, 0x31FF, "Mains voltage"),
    (0x3200, 0x32FF, "Voltage inside the device"),
    (0x3300, 0x33FF, "Output voltage"),
    (0x4000, 0x40FF, "Temperature"),
    (0x4100, 0x41FF, "Ambient temperature"),
    (0x4200, 0x42FF, "Device temperature"),
    (0x5000, 0x50FF, "Device hardware"),
    (0x6000, 0x60FF, "Device software"),
    (0x6100, 0x61FF, "Internal software"),
    (0x6200, 0x62FF, "User software"),
    (0x6300, 0x63FF, "Data set"),
    (0x7000, 0x70FF, "Additional modules"),
    (0x8000, 0x80FF, "Monitoring"),
    (0x8100, 0x810F, "Communication"),
    (0x8110, 0x8110, "CAN overrun (objects lost)"),
    (0x8120, 0x8120, "CAN in error passive mode"),
    (0x8130, 0x8130, "Life guard error or heartbeat error"),
    (0x8140, 0x8140, "Recovered from bus off"),
    (0x8150, 0x8150, "CAN-ID collision"),
    (0x8111, 0x81FF, "Communication"),
    (0x8200, 0x820F, "Protocol error"),
    (0x8210, 0x8210, "PDO not processed due to length error"),
    (0x8220, 0x8220, "PDO length exceeded"),
    (0x8230, 0x8230, "DAM MPDO not processed, destination object not available"),
    (0x8240, 0x8240, "Unexpected SYNC data length"),
    (0x8250, 0x8250, "RPDO timeout"),
    (0x8211, 0x82FF, "Protocol error"),
    (0x9000, 0x90FF, "External error"),
    (0xF000, 0xF0FF, "Additional functions"),
    (0xFF00, 0xFFFF, "Device specific"),
]

ERROR_REGISTER_BITS = {
    0: "Generic error",
    1: "Current",
    2: "Voltage",
    3: "Temperature",
    4: "Communication error",
    5: "Device profile specific",
    6: "Reserved",
    7: "Manufacturer specific",
}


def error_code_class(code: int) -> str:
    """The CiA 301 class of an emergency error code (most specific range first)."""
    best: tuple[int, str] | None = None
    for low, high, text in ERROR_CODE_CLASSES:
        if low <= code <= high and (best is None or high - low < best[0]):
            best = (high - low, text)
    return best[1] if best else "Unknown"


def error_register_bits(register: int) -> list[str]:
    return [text for bit, text in ERROR_REGISTER_BITS.items() if register >> bit & 1]


@dataclass(frozen=True)
class EmcyEvent:
    node_id: int
    code: int
    register: int
    data: bytes
    """The five manufacturer-specific bytes."""
    timestamp: float

    @property
    def is_reset(self) -> bool:
        return self.code == 0x0000

    @property
    def class_text(self) -> str:
        return error_code_class(self.code)

    @property
    def register_bits(self) -> list[str]:
        return error_register_bits(self.register)


def decode_emcy(node_id: int, data: bytes, timestamp: float | None = None) -> EmcyEvent:
    padded = bytes(data) + bytes(max(0, 8 - len(data)))
    return EmcyEvent(node_id, int.from_bytes(padded[0:2], "little"), padded[2], padded[3:8], timestamp or time.time())


EmcyCallback = Callable[[EmcyEvent], None]


class EmcyMonitor(can.Listener):
    """Keeps the last ``history`` EMCY telegrams per node (0x081..0x0FF)."""

    def __init__(self, history: int = 200) -> None:
        self._lock = threading.Lock()
        self._events: dict[int, deque[EmcyEvent]] = {}
        self._history = history
        self._callbacks: list[EmcyCallback] = []

    def add_callback(self, callback: EmcyCallback) -> None:
        self._callbacks.append(callback)

    def on_message_received(self, msg: can.Message) -> None:
        node_id = msg.arbitration_id - EMCY_BASE
        if msg.is_extended_id or msg.is_remote_frame or not 1 <= node_id <= 127 or msg.dlc == 0:
            return
        event = decode_emcy(node_id, bytes(msg.data), msg.timestamp)
        with self._lock:
            self._events.setdefault(node_id, deque(maxlen=self._history)).append(event)
        for callback in self._callbacks:
            callback(event)

    def history(self, node_id: int) -> list[EmcyEvent]:
        with self._lock:
            return list(self._events.get(node_id, ()))

    def last(self, node_id: int) -> EmcyEvent | None:
        with self._lock:
            events = self._events.get(node_id)
            return events[-1] if events else None

    def active(self, node_id: int) -> EmcyEvent | None:
        """The last EMCY unless the node has since sent an error reset (code 0x0000)."""
        last = self.last(node_id)
        return None if last is None or last.is_reset else last
