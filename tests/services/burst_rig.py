"""A burst of frames through a socketcand hub into a session's monitor while the monitoring process is busy
(issue 21 item 3), and the exact load of each one-second window to compare the monitor's points with.

The hub and the sender run in processes of their own (a gateway and another tool on the bus); this process runs
the session and its monitor, a thread burning CPU (the GIL is contended, as on a busy server) and, once, a stall
of the frame listener thread (frames wait in the socket and are counted late, in a catch-up). An independent
python-can client of the hub records every frame with the hub's timestamp: the exact bits (stuff bits included,
``busload.reference_bits``, bit by bit) per second of hub time are the true load.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import can

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.monitoring.monitor import RATE_WINDOW_S, Monitor, monitor_for
from drivebench.services.session_manager import SessionManager
from drivebench.transport.busload import reference_bits
from tests.conftest import wait_until

BITRATE = 500_000
HUB = """
import asyncio, sys
from drivebench.transport.hub import serve_hub
asyncio.run(serve_hub("127.0.0.1", int(sys.argv[1]), on_listening=lambda host, port: print("ready", flush=True)))
"""
SENDER = """
import sys, time, can
port, rate, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
total, sent, start = int(rate * seconds), 0, time.monotonic()
while sent < total:
    delay = start + sent / rate - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    # data that changes every frame: the stuff bits vary from frame to frame
    data = sent.to_bytes(4, "little") + bytes([sent * 7 & 0xFF, 0x55, sent >> 3 & 0xFF, 0xFF])
    bus.send(can.Message(arbitration_id=0x181 + sent % 4, is_extended_id=False, data=data))
    sent += 1
bus.shutdown()
"""


@dataclass
class BurstResult:
    points: dict[int, float]
    """The monitor's one-second load points (second of hub time -> percent)."""
    exact: dict[int, float]
    """The exact load of each second in which burst frames were on the bus."""
    frames_sent: int
    frames_counted: int
    peak_percent: float
    rates: list[tuple[float, float]]
    """Snapshots taken every 0.5 s during the burst (as the page polls): (frames/s shown, exact frames/s of the
    closed windows the snapshot names)."""

    def full_seconds(self) -> list[int]:
        """The seconds the burst filled from start to end (not the partial first and last)."""
        seconds = sorted(self.exact)
        return seconds[1:-1]

    def rates_during_burst(self) -> list[tuple[float, float]]:
        """The polled rates whose windows had burst frames (the sender process may start late on a busy machine)."""
        return [(shown, exact) for shown, exact in self.rates if exact]

    def worst_rate_error_percent(self) -> float:
        return max((abs(shown - exact) / exact * 100 for shown, exact in self.rates_during_burst()), default=0.0)

    def worst_error_percent(self) -> float:
        """Largest deviation of a point from the exact load, relative to the exact load (every burst second)."""
        return max(abs(self.points.get(second, 0.0) - load) / load * 100 for second, load in self.exact.items())


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextlib.contextmanager
def _hub() -> Iterator[int]:
    port = _free_port()
    process = subprocess.Popen([sys.executable, "-c", HUB, str(port)], stdout=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        yield port
    finally:
        process.terminate()
        process.wait(timeout=10)


class _Recorder(threading.Thread):
    """Every frame of the hub with its hub timestamp: exact bits per second of hub time."""

    def __init__(self, port: int) -> None:
        super().__init__(name="burst-reference", daemon=True)
        self.bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
        self.bits: dict[int, int] = defaultdict(int)
        self.frames: dict[int, int] = defaultdict(int)
        self.count = 0
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            msg = self.bus.recv(0.1)
            if msg is None or msg.is_error_frame:
                continue
            second = int(msg.timestamp)
            self.bits[second] += reference_bits(msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame,
                                                msg.dlc, bytes(msg.data))
            self.frames[second] += 1
            self.count += 1


class _Stall(can.Listener):
    """Holds up the frame listener thread once, ``after`` frames into the burst (a processing stall)."""

    def __init__(self, after: int, stall_s: float) -> None:
        self.after = after
        self.stall_s = stall_s
        self.seen = 0

    def on_message_received(self, msg: can.Message) -> None:
        self.seen += 1
        if self.seen == self.after:
            time.sleep(self.stall_s)


def _burn(stop: threading.Event) -> None:
    while not stop.is_set():
        sum(range(10_000))


def run_burst(registry: ProfileRegistry, *, rate: int = 2_000, seconds: float = 4.0,
              stall_s: float = 1.5) -> BurstResult:
    """Send ``rate`` frames/s for ``seconds`` through a hub; the monitor counts them in a busy process."""
    with _hub() as port:
        recorder = _Recorder(port)
        recorder.start()
        runner = asyncio.Runner()
        manager = SessionManager(registry)
        stop_burning = threading.Event()
        burner = threading.Thread(target=_burn, args=(stop_burning,), name="cpu-burner", daemon=True)
        try:
            session = runner.run(manager.open(f"socketcand:127.0.0.1:{port}/can0@{BITRATE}", "burst"))
            session.add_frame_listener(_Stall(int(rate * seconds / 3), stall_s))  # before the monitor: it waits too
            monitor = monitor_for(session)
            time.sleep(0.6)  # the hub lets a new client settle before relaying to it
            burner.start()
            sender = subprocess.Popen([sys.executable, "-c", SENDER, str(port), str(rate), str(seconds)])
            polled: list[tuple[int, float, int]] = []
            while sender.poll() is None:
                time.sleep(0.5)
                load, totals = (snapshot := monitor.snapshot())["load"], snapshot["totals"]
                if load["second"] is not None:  # and how many windows had closed: fewer than RATE_WINDOW_S at first
                    closed = sum(1 for at, _ in monitor.history() if at <= load["second"])
                    polled.append((load["second"], totals["rate"], max(1, min(RATE_WINDOW_S, closed))))
            assert sender.returncode == 0
            total = int(rate * seconds)
            _wait(lambda: recorder.count >= total and monitor.snapshot()["totals"]["frames"] >= total, 30)
            last = max(recorder.bits)
            _wait(lambda: _closed(monitor, last), 10)
            return _result(monitor, recorder, total, polled)
        finally:
            stop_burning.set()
            recorder.stop.set()
            recorder.join(timeout=5)
            recorder.bus.shutdown()
            runner.run(manager.close_all())
            runner.close()


def _closed(monitor: Monitor, second: int) -> bool:
    return any(int(at) == second for at, _ in monitor.history())


def _result(monitor: Monitor, recorder: _Recorder, total: int, polled: list[tuple[int, float, int]]) -> BurstResult:
    snapshot = monitor.snapshot()
    points = {int(at): load for at, load in monitor.history()}
    exact = {second: 100.0 * bits / BITRATE for second, bits in recorder.bits.items()}
    # a snapshot's frames/s is of the RATE_WINDOW_S windows closed up to the one it names (fewer just after start)
    rates = [(shown, sum(recorder.frames.get(s, 0) for s in range(newest - windows + 1, newest + 1)) / windows)
             for newest, shown, windows in polled]
    return BurstResult(points, exact, total, snapshot["totals"]["frames"], snapshot["load"]["peak_percent"], rates)


def _wait(check: Callable[[], object], timeout_s: float) -> None:
    assert wait_until(lambda: bool(check()), timeout_s), f"not met within {timeout_s} s"
