"""Emergency telegrams (CiA 301): received, decoded to code, class, error register bits; history per node.

The CiA 301 texts are English here (the trace's words) and in the reader's language where an event shows them
(:attr:`EmcyEvent.class_text`, :attr:`EmcyEvent.register_bits`, read when a page or the API is built)."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import can

from drivebench.i18n import N_, _

EMCY_BASE = 0x80

# CiA 301 emergency error code classes (high byte; 0x10 .. 0xFF).
ERROR_CODE_CLASSES = [
    (0x0000, 0x00FF, N_("Error reset or no error")),
    (0x1000, 0x10FF, N_("Generic error")),
    (0x2000, 0x20FF, N_("Current")),
    (0x2100, 0x21FF, N_("Current, device input side")),
    (0x2200, 0x22FF, N_("Current inside the device")),
    (0x2300, 0x23FF, N_("Current, device output side")),
    (0x3000, 0x30FF, N_("Voltage")),
    (0x3100, 0x31FF, N_("Mains voltage")),
    (0x3200, 0x32FF, N_("Voltage inside the device")),
    (0x3300, 0x33FF, N_("Output voltage")),
    (0x4000, 0x40FF, N_("Temperature")),
    (0x4100, 0x41FF, N_("Ambient temperature")),
    (0x4200, 0x42FF, N_("Device temperature")),
    (0x5000, 0x50FF, N_("Device hardware")),
    (0x6000, 0x60FF, N_("Device software")),
    (0x6100, 0x61FF, N_("Internal software")),
    (0x6200, 0x62FF, N_("User software")),
    (0x6300, 0x63FF, N_("Data set")),
    (0x7000, 0x70FF, N_("Additional modules")),
    (0x8000, 0x80FF, N_("Monitoring")),
    (0x8100, 0x810F, N_("Communication")),
    (0x8110, 0x8110, N_("CAN overrun (objects lost)")),
    (0x8120, 0x8120, N_("CAN in error passive mode")),
    (0x8130, 0x8130, N_("Life guard error or heartbeat error")),
    (0x8140, 0x8140, N_("Recovered from bus off")),
    (0x8150, 0x8150, N_("CAN-ID collision")),
    (0x8111, 0x81FF, N_("Communication")),
    (0x8200, 0x820F, N_("Protocol error")),
    (0x8210, 0x8210, N_("PDO not processed due to length error")),
    (0x8220, 0x8220, N_("PDO length exceeded")),
    (0x8230, 0x8230, N_("DAM MPDO not processed, destination object not available")),
    (0x8240, 0x8240, N_("Unexpected SYNC data length")),
    (0x8250, 0x8250, N_("RPDO timeout")),
    (0x8211, 0x82FF, N_("Protocol error")),
    (0x9000, 0x90FF, N_("External error")),
    (0xF000, 0xF0FF, N_("Additional functions")),
    (0xFF00, 0xFFFF, N_("Device specific")),
]

ERROR_REGISTER_BITS = {
    0: N_("Generic error"),
    1: N_("Current"),
    2: N_("Voltage"),
    3: N_("Temperature"),
    4: N_("Communication error"),
    5: N_("Device profile specific"),
    6: N_("Reserved"),
    7: N_("Manufacturer specific"),
}


UNKNOWN_CLASS = N_("Unknown")


def error_code_class(code: int) -> str:
    """The CiA 301 class of an emergency error code (most specific range first)."""
    best: tuple[int, str] | None = None
    for low, high, text in ERROR_CODE_CLASSES:
        if low <= code <= high and (best is None or high - low < best[0]):
            best = (high - low, text)
    return best[1] if best else UNKNOWN_CLASS


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
        """The CiA 301 class of the code in the current language."""
        return _(error_code_class(self.code))

    @property
    def register_bits(self) -> list[str]:
        """The error register's bits set, in the current language."""
        return [_(bit) for bit in error_register_bits(self.register)]


def decode_emcy(node_id: int, data: bytes, timestamp: float | None = None) -> EmcyEvent:
    padded = bytes(data) + bytes(max(0, 8 - len(data)))
    return EmcyEvent(node_id, int.from_bytes(padded[0:2], "little"), padded[2], padded[3:8], timestamp or time.time())


EmcyCallback = Callable[[EmcyEvent], None]


class EmcyMonitor(can.Listener):
    """Keeps the last ``history`` emergencies per node: a CAN listener for EMCY telegrams, and :meth:`record` for
    the emergencies another bus delivers."""

    def __init__(self, history: int = 200) -> None:
        self._lock = threading.Lock()
        self._events: dict[int, deque[EmcyEvent]] = {}
        self._history = history
        self._callbacks: list[EmcyCallback] = []

    def add_callback(self, callback: EmcyCallback) -> None:
        self._callbacks.append(callback)

    def on_message_received(self, msg: can.Message) -> None:
        """A CAN EMCY telegram (0x081..0x0FF)."""
        node_id = msg.arbitration_id - EMCY_BASE
        if msg.is_extended_id or msg.is_remote_frame or not 1 <= node_id <= 127 or msg.dlc == 0:
            return
        self.record(decode_emcy(node_id, bytes(msg.data), msg.timestamp))

    def record(self, event: EmcyEvent) -> None:
        """An emergency however it came (a CAN telegram, a CoE emergency in an EtherCAT slave's mailbox)."""
        with self._lock:
            self._events.setdefault(event.node_id, deque(maxlen=self._history)).append(event)
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
