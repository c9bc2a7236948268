"""Websocket fan-out of the monitor: 20 clients at 10 updates/s while the bus carries 8,000 frames/s.

The server (uvicorn, the real app) runs in this process with a session on a virtual bus; a generator thread sends
8,000 mixed frames/s on that bus (they reach the monitor through python-can's notifier thread, as an adapter's
would). The 20 websocket clients run in a process of their own and measure, per update, ``receive time -
server_time`` (update latency: built -> on the client) and the age of the newest trace row (frame on the bus ->
on the client, includes the up to 100 ms batching). Target: p99 update latency < 200 ms.

Runs (``MONITOR_BENCH_RUNS``, e.g. ``5:on,0.5:on,5:off``): CPython's GIL switch interval in ms, and
permessage-deflate on or off on the server (uvicorn's default is on; browsers ask for it, and it compresses each
update once per client). Besides what the clients see, the server side is measured in-process: update built ->
written to the client's socket (``_send_loop`` wrapped), and the event loop's lag (a 10 ms sleep, how late).
(A run through a `drivebench hub` socketcand gateway instead of the virtual bus was tried: python-can's socketcand
client then dominates the notifier thread's time and prints a line per partial TCP read.)
"""

from __future__ import annotations

import asyncio
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

CLIENTS = 20
FRAME_RATE = 8_000
DURATION_S = 20.0
WARMUP_S = 2.0
RUNS = os.environ.get("MONITOR_BENCH_RUNS", "5:on,0.5:on,5:off,0.5:off")
HEADER = ("| GIL switch interval, deflate | Frames/s sent (counted) | Updates per client per s "
          "| Update latency p50 / p99 / max | Server: built -> written p50 / p99 | Event loop lag p99 / max "
          "| Newest frame -> client p50 / p99 | Server CPU | Load avg | Target p99 < 200 ms |")


async def _clients(url: str, count: int, duration: float) -> dict[str, object]:
    import websockets

    latencies: list[float] = []
    ages: list[float] = []
    updates = [0] * count

    async def one(index: int) -> None:
        async with websockets.connect(url, max_size=None, open_timeout=60) as socket:
            await socket.recv()  # hello
            started = time.time()
            while time.time() - started < duration:
                message = json.loads(await socket.recv())
                now = time.time()
                if now - started < WARMUP_S:
                    continue
                updates[index] += 1
                latencies.append(now - message["server_time"])
                if message["trace"]:
                    ages.append(now - message["trace"][-1][message["trace_columns"].index("time")])

    cpu_started = time.process_time()
    await asyncio.gather(*(one(i) for i in range(count)))
    return {"latencies": latencies, "ages": ages, "updates": updates,
            "client_cpu": (time.process_time() - cpu_started) / duration}


def client_main() -> None:
    url, count, duration = sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
    print(json.dumps(asyncio.run(_clients(url, count, duration))))


def _free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _wait_port(port: int, timeout_s: float = 20.0) -> None:
    import socket

    deadline = time.time() + timeout_s
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                return
        except OSError:
            if time.time() > deadline:
                raise
            time.sleep(0.1)


def _percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float("nan")


def _instrument(written: list[float], lags: list[float]) -> None:
    """Wrap the feed's per-client send loop (built -> written) and run a loop-lag probe beside each feed."""
    import re

    from drivebench.web.ws import monitor as ws_monitor

    built_at = re.compile(r'"server_time": ([0-9.]+)')

    async def send_loop(client: ws_monitor.FeedClient) -> None:
        while True:
            await client.ready.wait()
            text = client.take()
            await client.websocket.send_text(text)
            found = built_at.search(text)
            if found:
                written.append(time.time() - float(found[1]))

    async def lag_probe() -> None:
        while True:
            started = time.perf_counter()
            await asyncio.sleep(0.01)
            lags.append(time.perf_counter() - started - 0.01)

    original_run = ws_monitor.Feed.run

    async def run_with_probe(feed: ws_monitor.Feed) -> None:
        probe = asyncio.create_task(lag_probe())
        try:
            await original_run(feed)
        finally:
            probe.cancel()

    ws_monitor._send_loop = send_loop  # type: ignore[assignment]
    ws_monitor.Feed.run = run_with_probe  # type: ignore[method-assign, assignment]


def run(switch_interval_s: float, deflate: bool) -> dict[str, float]:
    import can
    import uvicorn

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _monitor_results import mixed_trace

    from drivebench.services.monitoring.monitor import monitor_for
    from drivebench.web.app import create_app

    written: list[float] = []
    lags: list[float] = []
    _instrument(written, lags)
    sys.setswitchinterval(switch_interval_s)
    channel = f"bench-fanout-{os.getpid()}-{switch_interval_s}-{deflate}"
    app = create_app(buses=[f"virtual:{channel}@1000000"])
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning",
                                           ws_per_message_deflate=deflate))
    server_thread = threading.Thread(target=server.run, daemon=True)
    server_thread.start()
    while not server.started:
        time.sleep(0.05)
    session = app.state.drivebench.manager.list()[0]
    monitor = monitor_for(session)
    frames = mixed_trace(FRAME_RATE)  # one second's worth, sent over and over
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    stop = threading.Event()
    sent = [0]

    def generate() -> None:
        batch = FRAME_RATE // 100
        next_at = time.perf_counter()
        index = 0
        while not stop.is_set():
            for _ in range(batch):
                msg = frames[index % len(frames)]
                index += 1
                wire.send(can.Message(arbitration_id=msg.arbitration_id, data=msg.data,
                                      is_extended_id=msg.is_extended_id, is_error_frame=msg.is_error_frame))
            sent[0] = index
            next_at += 0.01
            delay = next_at - time.perf_counter()
            if delay > 0:
                time.sleep(delay)

    monitor.reset()
    generator = threading.Thread(target=generate, daemon=True)
    started = time.time()
    generator.start()
    cpu_started = time.process_time()
    url = f"ws://127.0.0.1:{port}/ws/sessions/{session.id}/monitor"
    result = subprocess.run([sys.executable, __file__, "--clients", url, str(CLIENTS), str(DURATION_S)],
                            capture_output=True, text=True)
    if result.returncode:
        raise RuntimeError(f"websocket clients failed:\n{result.stderr[-3000:]}")
    stop.set()
    generator.join()
    elapsed = time.time() - started
    server_cpu = time.process_time() - cpu_started
    deadline = time.time() + 15
    while True:  # the notifier may still be working through the virtual bus's queue
        snapshot = monitor.snapshot()
        counted = snapshot["totals"]["frames"] + snapshot["totals"]["errors"]
        if counted >= sent[0] or time.time() > deadline:
            break
        time.sleep(0.2)
    server.should_exit = True
    server_thread.join(timeout=10)
    wire.shutdown()
    sys.setswitchinterval(0.005)
    data = json.loads(result.stdout)
    latencies, ages, updates = data["latencies"], data["ages"], data["updates"]
    per_client = [n / (DURATION_S - WARMUP_S) for n in updates]
    figures = {
        "switch_ms": switch_interval_s * 1000, "rate": sent[0] / elapsed, "sent": sent[0], "counted": counted,
        "updates_mean": statistics.mean(per_client), "updates_min": min(per_client),
        "updates_max": max(per_client), "p50": _percentile(latencies, 0.5) * 1000,
        "p99": _percentile(latencies, 0.99) * 1000, "max": max(latencies) * 1000, "n": len(latencies),
        "age50": _percentile(ages, 0.5) * 1000, "age99": _percentile(ages, 0.99) * 1000,
        "cpu": 100 * server_cpu / elapsed, "load": os.getloadavg()[0], "client_cpu": 100 * data["client_cpu"],
        "deflate": deflate, "written50": _percentile(written, 0.5) * 1000,
        "written99": _percentile(written, 0.99) * 1000,
        "lag99": _percentile(lags, 0.99) * 1000, "lagmax": max(lags, default=0.0) * 1000,
    }
    print(f"switch interval {figures['switch_ms']:.1f} ms, deflate {'on' if deflate else 'off'}: "
          f"server built->written p50 {figures['written50']:.0f} ms p99 {figures['written99']:.0f} ms, "
          f"loop lag p99 {figures['lag99']:.0f} ms max {figures['lagmax']:.0f} ms; "
          f"{CLIENTS} clients, {figures['rate']:,.0f} frames/s, "
          f"{counted:,} of {sent[0]:,} counted; updates/client/s {figures['updates_min']:.1f}.."
          f"{figures['updates_max']:.1f}; update latency p50 {figures['p50']:.1f} ms p99 {figures['p99']:.1f} ms "
          f"max {figures['max']:.1f} ms; frame->client p50 {figures['age50']:.0f} ms p99 {figures['age99']:.0f} ms; "
          f"server CPU {figures['cpu']:.0f} % of a core, clients {figures['client_cpu']:.0f} %; "
          f"load average {figures['load']:.1f}")
    return figures


def main() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _monitor_results import machine, write_subsection

    runs = []
    for spec in RUNS.split(","):
        switch_ms, deflate = spec.split(":")
        runs.append(run(float(switch_ms) / 1000, deflate == "on"))
    lines = []
    for f in runs:
        verdict = "met" if f["p99"] < 200 else "NOT met"
        lines.append(
            f"| {f['switch_ms']:.1f} ms, {'on' if f['deflate'] else 'off'} | {f['rate']:,.0f} "
            f"({f['counted']:,.0f} of {f['sent']:,.0f}) | "
            f"{f['updates_mean']:.1f} (min {f['updates_min']:.1f}) | {f['p50']:.0f} / {f['p99']:.0f} / "
            f"{f['max']:.0f} ms | {f['written50']:.0f} / {f['written99']:.0f} ms | {f['lag99']:.0f} / "
            f"{f['lagmax']:.0f} ms | {f['age50']:.0f} / {f['age99']:.0f} ms | {f['cpu']:.0f} % | {f['load']:.1f} | "
            f"{verdict} |")
    table = "\n".join(lines)
    write_subsection("websocket fan-out (`benchmarks/monitor_fanout.py`)", f"""
{CLIENTS} websocket clients (separate process, `websockets`) on `/ws/sessions/{{id}}/monitor` for {DURATION_S:.0f} s
(first {WARMUP_S:.0f} s not measured) while a thread sends {FRAME_RATE:,} mixed frames/s on the session's virtual
bus (1 Mbit/s). Machine: {machine()}, shared with other work (load average in the table).

{HEADER}
|---|---|---|---|---|---|---|---|---|---|
{table}

Update latency: built on the server -> parsed by the client (the 20 clients share one process, so a client also
waits for the others' parsing). "Newest frame -> client" includes the up to 100 ms batching and the notifier's
backlog. The server's own part (built -> written) is the figure the server controls; the rest is the clients'
process and the machine (shared: see the load average, 2 cores).

Where the server's time goes: the bus threads (notifier; here also the generator) run Python for every frame, and
the event loop gives up the GIL on every socket write and, with permessage-deflate, on every compression - 20 of
each per update. Each time it may wait up to one switch interval to get the GIL back (the convoy effect), so the
per-update cost grows with clients x switch interval, and deflate doubles the hand-overs (and compresses the same
update 20 times). The rows compare the two remedies, start-up settings of the server process: `drivebench serve`
sets the 0.5 ms switch interval; permessage-deflate stays on (uvicorn's default, `ws_per_message_deflate`).
""")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--clients":
        client_main()
    else:
        main()
