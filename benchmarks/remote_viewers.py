"""Remote diagnostics viewers do not slow the bus (issue 8).

The real server (`drivebench serve --demo`, a child process with its simulated plant) is measured twice in the
same run: with no viewer, then with VIEWERS remote-diagnostics websockets (`/ws/remote/{token}`, opened through a
share link, in a separate client process). Each phase measures, for PHASE_S seconds:

* SDO round trips through the API (GET .../parameters/C00061, a read from the device each time): p50 / p99;
* the frames per second on the bus during a quiet window before the reads (the monitor's counters): a viewer
  must add no bus traffic, because the remote view renders from the heartbeat/EMCY consumers' cached state;
* the updates each viewer received (once a second each).

Prints a table and writes it to RESULTS.md under '## Remote diagnostics'.
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
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
VIEWERS = 25
PHASE_S = 12.0
QUIET_S = 5.0
SESSION = "demo-plant"
READ_URL = f"/api/sessions/{SESSION}/nodes/5/parameters/C00061"
HEADING = "## Remote diagnostics"


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float("nan")


async def _viewers(url: str, count: int, duration_s: float) -> list[int]:
    import websockets

    updates = [0] * count

    async def one(index: int) -> None:
        async with websockets.connect(url, max_size=None, open_timeout=60) as ws:
            started = time.monotonic()
            while time.monotonic() - started < duration_s:
                try:
                    await asyncio.wait_for(ws.recv(), timeout=max(0.1, duration_s - (time.monotonic() - started)))
                except TimeoutError:
                    break
                updates[index] += 1

    await asyncio.gather(*(one(i) for i in range(count)))
    return updates


def viewer_main() -> None:
    url, count, duration_s = sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
    print(json.dumps(asyncio.run(_viewers(url, count, duration_s))))


def _frames(client: httpx.Client) -> int:
    return int(client.get(f"/api/sessions/{SESSION}/monitor", params={"trace": 0}).json()["totals"]["frames"])


def _phase(client: httpx.Client, seconds: float) -> dict[str, float]:
    frames_before, started = _frames(client), time.monotonic()
    time.sleep(QUIET_S)  # the bus on its own: heartbeats, PDOs, and whatever the viewers cause
    quiet_rate = (_frames(client) - frames_before) / (time.monotonic() - started)
    latencies: list[float] = []
    started = time.monotonic()
    while time.monotonic() - started < seconds:
        sent = time.perf_counter()
        response = client.get(READ_URL)
        latencies.append((time.perf_counter() - sent) * 1000)
        response.raise_for_status()
    return {"reads": len(latencies), "p50": statistics.median(latencies), "p99": _percentile(latencies, 0.99),
            "frames_per_s": quiet_rate}


def main() -> dict[str, object]:
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as scratch:
        env = dict(os.environ, DRIVEBENCH_DATABASE_URL=f"sqlite:///{scratch}/bench.sqlite",
                   DRIVEBENCH_USER_PROFILES_DIR=f"{scratch}/profiles")
        server = subprocess.Popen([sys.executable, "-m", "drivebench.cli", "serve", "--demo", "--port", str(port)],
                                  env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            with httpx.Client(base_url=base, timeout=10) as client:
                deadline = time.monotonic() + 60
                while True:
                    try:
                        if client.get("/api/health").status_code == 200:
                            break
                    except httpx.TransportError:
                        pass
                    if time.monotonic() > deadline:
                        raise RuntimeError("the server did not start within 60 s")
                    time.sleep(0.2)
                time.sleep(2.0)  # heartbeats settle
                alone = _phase(client, PHASE_S)
                token = client.post("/api/share-links", json={"ttl_minutes": 30, "label": "benchmark"}).json()["token"]
                ws_url = f"ws://127.0.0.1:{port}/ws/remote/{token}"
                viewers = subprocess.Popen([sys.executable, __file__, "--viewers", ws_url, str(VIEWERS),
                                            str(PHASE_S + QUIET_S + 4)], stdout=subprocess.PIPE, text=True)
                time.sleep(2.0)  # all viewers connected
                watched = _phase(client, PHASE_S)
                out, _ = viewers.communicate(timeout=120)
                updates = json.loads(out)
        finally:
            server.terminate()
            server.wait(timeout=30)
    return {"alone": alone, "watched": watched, "updates": updates}


def _table(result: dict[str, object]) -> str:
    alone, watched = result["alone"], result["watched"]
    updates = result["updates"]
    assert isinstance(alone, dict) and isinstance(watched, dict) and isinstance(updates, list)
    rows = [
        f"{HEADING}\n",
        f"`benchmarks/remote_viewers.py`, {time.strftime('%Y-%m-%d %H:%M')} on {platform.node()} "
        f"({platform.machine()}, Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}); "
        f"`drivebench serve --demo` in a child process, {VIEWERS} remote-diagnostics websockets in another, "
        f"per phase {QUIET_S:g} s quiet (bus frames/s) then {PHASE_S:g} s of back-to-back SDO reads through the API.\n",
        "| Phase | Bus frames/s (quiet window) | SDO reads via API | Round trip p50 / p99 |",
        "|---|---|---|---|",
    ]
    for label, phase in (("no viewer", alone), (f"{VIEWERS} remote viewers", watched)):
        rows.append(f"| {label} | {phase['frames_per_s']:.1f} | {phase['reads']:,} "
                    f"| {phase['p50']:.1f} / {phase['p99']:.1f} ms |")
    extra_frames = round(watched["frames_per_s"] - alone["frames_per_s"], 1) + 0.0  # no "-0.0"
    rows += [
        "",
        f"Updates per viewer: min {min(updates)}, max {max(updates)} (one a second). p50 ratio watched / alone: "
        f"{watched['p50'] / alone['p50']:.2f}. Bus frames/s with viewers minus without: {extra_frames:+.1f} "
        "(heartbeats and PDOs only; the viewers add no traffic: they render from cached heartbeat/EMCY state).",
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
        viewer_main()
    else:
        section = _table(main())
        print(section)
        _write_results(section)
