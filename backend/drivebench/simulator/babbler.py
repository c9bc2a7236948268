"""A babbling node: one COB-ID sent back to back, as a CAN controller stuck in a transmit loop does.

It paces its frames at the bus's full frame rate for that frame (bit rate / exact bits per frame, see
:func:`~drivebench.transport.busload.message_bits`), so the monitor's load reads 100 %; the virtual bus itself
has no bandwidth and would take more. On a real bus the babbler wins every arbitration against higher
identifiers: :meth:`Babbler.starves` tells the plant which of its nodes' frames can no longer get on the bus.
"""

from __future__ import annotations

import threading
import time

import can

from drivebench.errors import TransportError
from drivebench.transport.bus import BusSpec, ObservedBus, open_bus
from drivebench.transport.busload import message_bits

DEFAULT_COB_ID = 0x001
"""Not used by CiA 301's predefined connection set, and above NMT (0x000) only: it wins against everything else."""
TICK_S = 0.005
MAX_BURST = 400
"""Frames sent in one go at most, so a late thread catches up without a flood far beyond the bit rate."""


class Babbler:
    """Sends ``cob_id`` with ``data`` at ``load_percent`` of the bus's capacity until :meth:`stop`."""

    def __init__(self, spec: BusSpec, cob_id: int = DEFAULT_COB_ID, data: bytes = bytes(8), *,
                 load_percent: float = 100.0) -> None:
        if not 0 <= cob_id <= 0x7FF:
            raise ValueError("a babbler sends an 11-bit COB-ID")
        if not 0 < load_percent <= 100:
            raise ValueError("load_percent is 0 < load <= 100")
        self.spec = spec
        self.cob_id = cob_id
        self.data = bytes(data[:8])
        self.load_percent = load_percent
        frame = can.Message(arbitration_id=cob_id, data=self.data, is_extended_id=False)
        self.frames_per_s = spec.bitrate * load_percent / 100.0 / message_bits(frame)
        self.sent = 0
        self._bus: ObservedBus | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def starves(self, cob_id: int) -> bool:
        """Whether a frame with ``cob_id`` loses every arbitration (the babbler holds the whole bus)."""
        return self.running and self.load_percent >= 100 and cob_id > self.cob_id

    def start(self) -> Babbler:
        self._bus = open_bus(self.spec)
        self._thread = threading.Thread(target=self._run, name=f"babbler-0x{self.cob_id:03X}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        if self._bus is not None:
            self._bus.shutdown()

    def _run(self) -> None:
        assert self._bus is not None
        started = time.monotonic()
        while not self._stop.is_set():
            due = int((time.monotonic() - started) * self.frames_per_s) - self.sent
            for _ in range(min(due, MAX_BURST)):
                try:
                    self._bus.send(can.Message(arbitration_id=self.cob_id, data=self.data, is_extended_id=False))
                except TransportError:
                    break
                self.sent += 1
            if due > MAX_BURST:  # too far behind (a busy machine): forget the backlog instead of bursting
                self.sent += due - MAX_BURST
            self._stop.wait(TICK_S)
