"""Join one channel of the socketcand hub to a python-can bus (an adapter, or a ``virtual`` channel).

Frames the hub's clients send on the channel are written to the bus by a sender thread fed through a bounded
queue (a slow adapter loses frames, counted, instead of stalling the hub); frames read from the bus are handed
to the hub, which relays them to every client of the channel. Remote frames cannot travel through socketcand
and are counted as dropped.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass

import can

from drivebench.transport.bus import BusSpec, ObservedBus, open_bus

log = logging.getLogger(__name__)

POLL_S = 0.1
RETRY_AFTER_ERROR_S = 1.0

Deliver = Callable[[can.Message], None]


@dataclass(frozen=True)
class BridgeStats:
    spec: str
    channel: str
    frames_to_bus: int
    frames_from_bus: int
    frames_dropped: int  # queue full (the adapter is slower than the clients) or remote frames from the bus
    send_errors: int


class BusBridge:
    """A python-can bus as one more member of a hub channel."""

    def __init__(self, spec: BusSpec | str, channel: str = "can0", *, queue_frames: int = 4096) -> None:
        self.spec = spec if isinstance(spec, BusSpec) else BusSpec.parse(spec)
        self.channel = channel
        self._outgoing: queue.Queue[can.Message] = queue.Queue(maxsize=queue_frames)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._bus: ObservedBus | None = None
        # Each counter has one writer thread: the hub's loop (queue full), the reader, the sender.
        self.frames_to_bus = 0
        self.frames_from_bus = 0
        self.frames_overrun = 0
        self.remote_frames_dropped = 0
        self.send_errors = 0

    def start(self, deliver: Deliver) -> None:
        """Open the bus (raises :class:`~drivebench.errors.AdapterUnavailable`) and start moving frames."""
        self._bus = open_bus(self.spec)
        for name, target in (("reader", self._read), ("sender", self._write)):
            thread = threading.Thread(target=target, args=(deliver,) if name == "reader" else (),
                                      name=f"hub-bridge-{name}-{self.spec}", daemon=True)
            thread.start()
            self._threads.append(thread)
        log.info("hub channel %s bridged to %s", self.channel, self.spec)

    def offer(self, msg: can.Message) -> None:
        try:
            self._outgoing.put_nowait(msg)
        except queue.Full:
            self.frames_overrun += 1

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2)
        self._threads.clear()
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def stats(self) -> BridgeStats:
        return BridgeStats(str(self.spec), self.channel, self.frames_to_bus, self.frames_from_bus,
                           self.frames_overrun + self.remote_frames_dropped, self.send_errors)

    def _read(self, deliver: Deliver) -> None:
        bus = self._bus
        assert bus is not None
        while not self._stop.is_set():
            try:
                msg = bus.recv(POLL_S)
            except can.CanError as exc:
                log.warning("bridge %s: cannot read: %s", self.spec, exc)
                self._stop.wait(RETRY_AFTER_ERROR_S)
                continue
            if msg is None:
                continue
            if msg.is_remote_frame:
                self.remote_frames_dropped += 1
                continue
            self.frames_from_bus += 1
            deliver(msg)

    def _write(self) -> None:
        bus = self._bus
        assert bus is not None
        while not self._stop.is_set():
            try:
                msg = self._outgoing.get(timeout=POLL_S)
            except queue.Empty:
                continue
            try:
                bus.send(msg)
                self.frames_to_bus += 1
            except can.CanError as exc:
                self.send_errors += 1
                log.warning("bridge %s: cannot send 0x%X: %s", self.spec, msg.arbitration_id, exc)
