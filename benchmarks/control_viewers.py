"""Viewers of a node's Control tab do not delay a quick stop (issue 27 item 7).

The real app with the demo plant (its 5 ms device latency) runs in uvicorn in this process, a python-can bus on the
plant's virtual channel watches the wire. Measured twice in the same run, with no viewer and with VIEWERS control
panel websockets on node 5 (``/ws/sessions/demo-plant/nodes/5/control``, in a client process of their own, USERS
users): STOPS quick stops through the API (``POST …/control/commands/quick_stop``), each timed from the moment
the request is sent to the moment the quick stop's control-word write is on the wire; and the SDO requests per
second to node 5 before the stops. The target: the quick stop goes out within 50 ms with 200 viewers.

Prints a table and writes it to RESULTS.md under '## Control panel viewers'.
"""

from __future__ import annotations

import asyncio
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import httpx
import uvicorn

from drivebench.config import settings
from drivebench.services.control.drive_guard import guard_for
from drivebench.services.control.drive_words import family_of
from drivebench.services.params import lookup
from drivebench.web.app import create_app

ROOT = Path(__file__).resolve().parents[1]

VIEWERS = 200
USERS = 10
STOPS = 30
QUIET_S = 5.0
NODE = 5
SESSION = "demo-plant"
HEADING = "## Control panel viewers"


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float("nan")


async def _viewers(base: str, count: int, duration_s: float) -> list[int]:
    import websockets

    updates = [0] * count

    async def one(index: int) -> None:
        url = f"{base}/ws/sessions/{SESSION}/nodes/{NODE}/control?panel=bench{index}&operator=viewer{index}"
        async with websockets.connect(url, max_size=None, open_timeout=120,
                                      additional_headers={"X-DriveBench-User": f"viewer{index % USERS}"}) as ws:
            started = time.monotonic()
            while time.monotonic() - started < duration_s:
                try:
                    await asyncio.wait_for(ws.recv(), timeout=max(0.1, duration_s - (time.monotonic() - started)))
                except TimeoutError:
                    break
                updates[index] += 1

    await asyncio.gather(*(one(i) for i in range(count)))
    return updates


class Wire(can.Listener):
    """Requests to the node on the wire: how many, and when the control word was last written."""

    def __init__(self, control: bytes) -> None:
        self.control = control
        self.requests = 0
        self.writes: list[float] = []
        self.lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id != 0x600 + NODE:
            return
        with self.lock:
            self.requests += 1
            if msg.data[0] & 0xE0 == 0x20 and bytes(msg.data[1:4]) == self.control:
                self.writes.append(msg.timestamp or time.time())


def _stops(client: httpx.Client, wire: Wire) -> list[float]:
    latencies = []
    for _ in range(STOPS):
        with wire.lock:
            seen = len(wire.writes)
        sent = time.time()
        client.post(f"/api/sessions/{SESSION}/nodes/{NODE}/control/commands/quick_stop").raise_for_status()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with wire.lock:
                if len(wire.writes) > seen:
                    latencies.append((wire.writes[seen] - sent) * 1000)
                    break
            time.sleep(0.001)
        time.sleep(0.3)
    return latencies


def _requests_per_s(wire: Wire) -> float:
    with wire.lock:
        before = wire.requests
    time.sleep(QUIET_S)
    with wire.lock:
        return (wire.requests - before) / QUIET_S


def main() -> dict[str, object]:
    if hasattr(settings, "control_panels_per_node"):  # the code before issue 27 item 7 had no limits
        settings.control_panels_per_node = VIEWERS + 10
        settings.control_panels_per_user = VIEWERS
    channel = f"bench-viewers-{os.getpid()}"
    app = create_app(plant_file=ROOT / "plants" / "demo.json", plant_bus=f"virtual:{channel}@500000")
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.05)
    try:
        session = app.state.drivebench.manager.get(SESSION)
        node = session.node(NODE)
        fam = family_of(node.catalog)
        assert fam is not None
        item = lookup.resolve(node, fam.control_ref)
        wire = Wire(bytes([item.index & 0xFF, item.index >> 8, item.subindex]))
        bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        notifier = can.Notifier(bus, [wire])
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
                time.sleep(2.0)
                alone = {"requests_per_s": _requests_per_s(wire), "stops": _stops(client, wire)}
                viewers = subprocess.Popen([sys.executable, __file__, "--viewers", f"ws://127.0.0.1:{port}",
                                            str(VIEWERS), "300"], stdout=subprocess.PIPE, text=True)
                deadline = time.monotonic() + 60
                while guard_for(session).panels(NODE) < VIEWERS and time.monotonic() < deadline:
                    time.sleep(0.2)
                opened = guard_for(session).panels(NODE)
                time.sleep(2.0)
                watched = {"requests_per_s": _requests_per_s(wire), "stops": _stops(client, wire),
                           "opened": opened}
                viewers.terminate()
                viewers.wait(timeout=30)
        finally:
            notifier.stop()
            bus.shutdown()
    finally:
        server.should_exit = True
        thread.join(timeout=20)
    return {"alone": alone, "watched": watched}


def _row(label: str, phase: dict[str, object]) -> str:
    stops = phase["stops"]
    assert isinstance(stops, list)
    return (f"| {label} | {len(stops)} | {statistics.median(stops):.1f} / {_percentile(stops, 0.95):.1f} / "
            f"{max(stops):.1f} ms | {phase['requests_per_s']:.1f} |")


def _table(result: dict[str, object]) -> str:
    alone, watched = result["alone"], result["watched"]
    assert isinstance(alone, dict) and isinstance(watched, dict)
    stops = watched["stops"]
    assert isinstance(stops, list)
    verdict = "met" if stops and max(stops) <= 50 else "NOT met"
    rows = [
        f"{HEADING}\n",
        f"`benchmarks/control_viewers.py`, {time.strftime('%Y-%m-%d %H:%M')} on {platform.node()} "
        f"({platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, load average "
        f"{os.getloadavg()[0]:.1f}); the app with the demo plant (5 ms device latency) in uvicorn, "
        f"{watched['opened']} of {VIEWERS} control panel websockets on node {NODE} ({USERS} users) in a client "
        f"process; {STOPS} quick stops through the API each phase, timed from the request to the control-word write "
        "on the wire.\n",
        "| Phase | Quick stops | Request -> write on the wire p50 / p95 / max | SDO requests/s to the node "
        "(before the stops) |",
        "|---|---|---|---|",
        _row("no viewer", alone),
        _row(f"{VIEWERS} viewers", watched),
        "",
        f"Target (a quick stop out within 50 ms with {VIEWERS} viewers watching): {verdict}. The viewers share one "
        "status poll, so the requests per second are one panel's; the stop goes before any read waiting for the node.",
        "",
    ]
    return "\n".join(rows)


def _write_results(section: str) -> None:
    path = ROOT / "benchmarks" / "RESULTS.md"
    text = path.read_text(encoding="utf-8")
    start = text.find(HEADING + "\n")
    if start == -1:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        end = text.find("\n## ", start + len(HEADING))
        text = text[:start] + section + (text[end + 1:] if end != -1 else "")
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--viewers":
        print(json.dumps(asyncio.run(_viewers(sys.argv[2], int(sys.argv[3]), float(sys.argv[4])))))
    else:
        section = _table(main())
        print(section)
        _write_results(section)
