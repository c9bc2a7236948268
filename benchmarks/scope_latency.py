"""Scope display latency and the sample stream against the bus (issue 31): the app served by uvicorn with the demo
plant, a recording of the CiA 402 servo (node 7: 0x6064, 0x606C; sampled by PDO at ``--period-ms``, default 1 ms)
started over the HTTP API, watched by three real websocket clients (``websockets``, standing in for three browsers:
three Chromiums beside the server are too heavy for this shared 2-core machine; a browser adds its drawing, not the
transport measured here).

Reported: the end-to-end latency from the moment a second python-can bus on the plant's virtual channel sees
sample n's SYNC to the moment a client receives the row of sample n (p50, p99, max, per client and together; the
server batches at most ten messages a second, so ~100 ms is the design's ceiling), and the frames against the
samples: the TPDO frames the drive sent on the bus, the samples the clients received with a value, and how many
of those equal, in SYNC number and value, the TPDO frame that carried them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import struct
import sys
import threading
import time
from pathlib import Path
from typing import Any

import can
import httpx
import uvicorn
import websockets

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _monitor_results import machine, write_section

from drivebench.config import REPO_ROOT, settings
from drivebench.services.scope import pdo_source, runs
from drivebench.services.storage import database
from drivebench.web.app import create_app
from drivebench.web.ws import scope as scope_socket

HEADING = "## Scope: display latency with three viewers, samples against the bus"
AXIS = 7
CLIENTS = 3
API = "/api/sessions/demo-plant"


class Wire(can.Listener):
    """SYNC arrival times by SYNC number and node 7's TPDO frames as they came."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.syncs: list[float] = []
        self.frames: list[tuple[int, int, bytes]] = []
        """(newest SYNC number when it arrived, COB-ID, data) of node 7's TPDO frames, in bus order."""
        self.counting = False

    def on_message_received(self, msg: can.Message) -> None:
        now = time.monotonic()
        with self.lock:
            if not self.counting:
                return
            if msg.arbitration_id == 0x080:
                self.syncs.append(now)
            elif 0x180 <= msg.arbitration_id < 0x580 and msg.arbitration_id & 0x7F == AXIS and self.syncs:
                self.frames.append((len(self.syncs) - 1, msg.arbitration_id, bytes(msg.data)))


async def watch(url: str, until: float, seen: list[tuple[int, float, list[Any]]]) -> None:
    async with websockets.connect(url, max_size=None) as socket:
        while time.monotonic() < until:
            try:
                text = await asyncio.wait_for(socket.recv(), timeout=max(0.1, until - time.monotonic()))
            except TimeoutError:
                break
            arrived = time.monotonic()
            message = json.loads(text)
            if message["type"] == "rows":
                seen.extend((row[0], arrived, row[2:]) for row in message["rows"])


def answered(seen: list[tuple[int, int, bytes]], cobs: set[int], lag: int) -> dict[int, dict[int, bytes]]:
    """Each frame of the recording's TPDOs by the SYNC it answers, as CiA 301 has a "synchronous every SYNC" TPDO
    answer: each SYNC once, in order (the frame after the one for SYNC n answers n + 1 even when it comes after a
    later SYNC), never a SYNC not sent yet; a node more than ``lag`` SYNCs behind skipped SYNCs."""
    found: dict[int, dict[int, bytes]] = {}
    expected: dict[int, int] = {}
    for stamp, cob, data in seen:
        if cob not in cobs:
            continue
        sample = stamp if cob not in expected or stamp - expected[cob] > lag else min(expected[cob], stamp)
        expected[cob] = sample + 1
        found.setdefault(sample, {})[cob] = data
    return found


def percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(share * (len(ordered) - 1)))] if ordered else float("nan")


def run(seconds: float, period_ms: float) -> dict[str, Any]:
    channel = f"scope-latency-{os.getpid()}"
    app = create_app(plant_file=REPO_ROOT / "plants" / "demo.json", plant_bus=f"virtual:{channel}@500000",
                     latency="0ms")
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning",
                                           timeout_graceful_shutdown=5))
    import socket as sockets

    sock = sockets.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    wire_bus = can.Bus(interface="virtual", channel=channel)
    wire = Wire()
    notifier = can.Notifier(wire_bus, [wire])
    try:
        while not server.started:
            time.sleep(0.05)
        base = f"http://127.0.0.1:{port}"
        body = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x606C"}],
                "period_ms": period_ms, "length_s": seconds * 10, "trigger": {"mode": "free"}, "name": "latency"}
        with httpx.Client(base_url=base, timeout=30) as http:
            asked = http.post(f"{API}/scope/run", json=body)
            if asked.status_code == 428:
                problem = asked.json()
                with wire.lock:
                    wire.counting = True  # SYNC 0 is the first one after this start
                asked = http.post(f"{API}/scope/run", json={**body, "confirm": problem["confirm_node"],
                                                            "confirm_values": problem["confirm_values"]})
            assert asked.status_code == 201 and asked.json()["source"] == "pdo", asked.text
            session = app.state.drivebench.manager.get("demo-plant")
            recording = runs.current(session)
            infos = recording.infos
            part = getattr(recording.source, "pdo", recording.source)  # the joined source's PDO part
            cobs = {tpdo.cob_id for tpdo in part.plan.tpdos}
            seen: list[list[tuple[int, float, list[Any]]]] = [[] for _ in range(CLIENTS)]
            until = time.monotonic() + seconds
            url = f"ws://127.0.0.1:{port}/ws/sessions/demo-plant/scope"

            async def all_clients() -> None:
                await asyncio.gather(*(watch(url, until, found) for found in seen))

            asyncio.run(all_clients())
            stopped = http.post(f"{API}/scope/run/stop").json()
    finally:
        notifier.stop()
        wire_bus.shutdown()
        server.should_exit = True
        thread.join(timeout=15)
        sock.close()
    with wire.lock:
        syncs, seen_frames = list(wire.syncs), list(wire.frames)
    frames = answered(seen_frames, cobs, max(3, math.ceil(pdo_source.WAIT_S * 1000 / period_ms)))
    start_s = min(arrived for found in seen for _, arrived, _ in found) + 1.0  # past the backlog a late viewer gets
    latencies = [[arrived - syncs[sample] for sample, arrived, _ in found
                  if sample < len(syncs) and arrived >= start_s] for found in seen]
    carried, equal = 0, 0
    for sample, _, values in seen[0]:
        for position, value in enumerate(values):
            if value is None:
                continue
            carried += 1
            matches = [struct.unpack_from("<i", data, 4 * position)[0] for data in frames.get(sample, {}).values()
                       if len(data) >= 4 * position + 4]
            equal += any(infos[position].value(raw) == value for raw in matches)
    return {"seconds": seconds, "period_ms": period_ms, "syncs": len(syncs),
            "tpdo_frames": sum(cob in cobs for _, cob, _ in seen_frames),
            "rows": [len(found) for found in seen], "carried": carried, "equal": equal,
            "latency_ms": [{"p50": 1000 * percentile(found, 0.5), "p99": 1000 * percentile(found, 0.99),
                            "max": 1000 * max(found, default=float("nan")), "count": len(found)}
                           for found in latencies],
            "all_ms": {"p50": 1000 * percentile([v for found in latencies for v in found], 0.5),
                       "p99": 1000 * percentile([v for found in latencies for v in found], 0.99)},
            "restored": stopped.get("restored", []), "load": os.getloadavg()[0]}


def write_results(result: dict[str, Any]) -> None:
    rows = "\n".join(f"| client {i + 1} | {found['count']} | {found['p50']:.1f} | {found['p99']:.1f} | "
                     f"{found['max']:.1f} |" for i, found in enumerate(result["latency_ms"]))
    body = f"""Written by `benchmarks/scope_latency.py`: the app served by uvicorn with the demo plant, node 7
(0x6064, 0x606C) sampled by PDO at a {result["period_ms"]:g} ms SYNC for {result["seconds"]:g} s, watched by {CLIENTS}
real websocket clients (the `websockets` library standing in for three browsers: three Chromiums beside the
server are too heavy for this shared machine; a browser adds its drawing, not the transport measured here).
Machine: {machine()}, shared with other work; {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}.

End-to-end latency, from a second python-can bus seeing sample n's SYNC to a client receiving the row of sample n
(the first second after connecting left out: a viewer who connects gets the last samples as a backlog first):

| Viewer | Rows | p50 [ms] | p99 [ms] | max [ms] |
|---|---|---|---|---|
{rows}
| all three | | {result["all_ms"]["p50"]:.1f} | {result["all_ms"]["p99"]:.1f} | |

Target: p99 < 100 ms. A row goes out as soon as every sending node answered its SYNC (it waits up to
`pdo_source.WAIT_S` only for a node that fell behind) and the scope socket sends at most one message per
`MIN_INTERVAL_S` of `web/ws/scope.py` ({scope_socket.MIN_INTERVAL_S * 1000:.0f} ms); what is above that is this
machine's load (load average {result["load"]:.1f} at the end).

Samples against the bus: SYNCs seen {result["syncs"]}; TPDO frames node 7 sent {result["tpdo_frames"]}; channel values
client 1 received {result["carried"]} (two per frame), of which {result["equal"]} equal in SYNC number and value the
TPDO frame that carried them (each frame put to the SYNC it answers by the in-order rule of a "synchronous every
SYNC" TPDO, as the source does; a frame the source got too late is a gap in the samples, not a different value).
"""
    write_section(HEADING, body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--period-ms", type=float, default=1.0)
    args = parser.parse_args()
    db_file = Path(f"/tmp/scope-latency-{os.getpid()}.db")
    settings.database_url = f"sqlite:///{db_file}"
    try:
        result = run(args.seconds, args.period_ms)
    finally:
        database.dispose(settings.database_url)
        db_file.unlink(missing_ok=True)
    print(json.dumps(result, indent=1)[:3000])
    write_results(result)


if __name__ == "__main__":
    main()
