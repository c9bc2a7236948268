"""Idle cost (issue 21 item 4): CPU of an idle `drivebench serve --demo` (the demo plant's simulated drives, nobody
connected), and of an idle server on a bus with no page open: `serve --bus socketcand:…` on a `drivebench hub`
nobody else uses, the same with the demo plant's drives on the hub (`drivebench simulate` in another process: the
heartbeats of a real machine), and `serve --bus virtual:…` with no simulator on it.

Each server runs in a process of its own with a fresh database; after it answers /api/health and settles, its CPU time
(user + system, /proc/<pid>/stat, every thread) is read over MEASURE_S. Targets: < 2 % of one core for the demo
server, < 1 % on a bus.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _monitor_results import machine, write_section

HEADING = "## Idle cost"
MEASURE_S = float(os.environ.get("IDLE_CPU_MEASURE_S", "30"))
SETTLE_S = 5.0
TARGET_PERCENT = 2.0
BUS_TARGET_PERCENT = 1.0


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def cpu_seconds(pid: int) -> float:
    """utime + stime of the process (all its threads), in seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(serve_args: list[str]) -> tuple[float, float]:
    """(CPU % of one core over MEASURE_S, load average at the end) of `drivebench serve` with ``serve_args``."""
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp}/idle.db"}
        server = subprocess.Popen([sys.executable, "-m", "drivebench.cli", "serve", *serve_args, "--port", str(port)],
                                  env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=2).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.monotonic() > deadline or server.poll() is not None:
                    raise RuntimeError("the server did not start")
                time.sleep(0.2)
            time.sleep(SETTLE_S)
            cpu_before, wall_before = cpu_seconds(server.pid), time.monotonic()
            time.sleep(MEASURE_S)
            cpu_after, wall_after = cpu_seconds(server.pid), time.monotonic()
        finally:
            server.terminate()
            server.wait(timeout=15)
    return 100.0 * (cpu_after - cpu_before) / (wall_after - wall_before), os.getloadavg()[0]


def _listening(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


def measure_on_hub(*, drives: bool = False) -> tuple[float, float]:
    """An idle server on a socketcand hub (the hub is another process, not counted); with ``drives`` the demo
    plant's simulated drives are on the bus in a process of their own (their heartbeats are the bus's traffic), as
    on a real machine where nobody has a page open."""
    port = _free_port()
    bus = f"socketcand:127.0.0.1:{port}/can0"
    children = [subprocess.Popen([sys.executable, "-m", "drivebench.cli", "hub", "--port", str(port)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 30
        while not _listening(port):
            if time.monotonic() > deadline:
                raise RuntimeError("the hub did not start")
            time.sleep(0.1)
        if drives:
            children.append(subprocess.Popen([sys.executable, "-m", "drivebench.cli", "simulate", "--bus", bus],
                                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        return measure(["--bus", bus])
    finally:
        for child in reversed(children):
            child.terminate()
            child.wait(timeout=15)


def main() -> int:
    rows = [("Idle demo server (`serve --demo`)", TARGET_PERCENT, *measure(["--demo"])),
            ("Idle server on a socketcand hub without traffic (`serve --bus socketcand:…`)", BUS_TARGET_PERCENT,
             *measure_on_hub()),
            ("Idle server on a socketcand hub with the demo plant's drives in another process (`simulate`: their "
             "heartbeats on the bus), no page open", BUS_TARGET_PERCENT, *measure_on_hub(drives=True)),
            ("Idle server on a virtual bus without a simulator (`serve --bus virtual:…`)", BUS_TARGET_PERCENT,
             *measure(["--bus", f"virtual:idle-{os.getpid()}@500000"]))]
    lines = "\n".join(f"| {name} | {percent:.2f} % of one core | < {target:g} %: "
                       f"{'met' if percent < target else 'NOT met'} | {load:.1f} |"
                       for name, target, percent, load in rows)
    body = f"""Written by `benchmarks/idle_cpu.py`. Idle servers, nobody connected: CPU time of the server process (all
threads, /proc/<pid>/stat) over {MEASURE_S:.0f} s after start-up and {SETTLE_S:.0f} s to settle. Machine: {machine()},
shared with other work; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.

| Server | CPU | Target | Load average (1 min) at the end |
|---|---|---|---|
{lines}

Before (the plant's ticker polled every node every 2 ms): 2.97 % for the demo server with this script on this machine
(2026-11-25, load average ~9); the issue measured 14 % on its machine. The rest of the idle server (heartbeat consumer,
guarding thread, event loop) was ~0.2 % of that; the plant's ticker now sleeps until a heartbeat is due or a frame or
write wakes it. On a bus without traffic the server's threads wait in their receive calls. The simulated
EtherCAT master (added to the demo plant later) ticked its slaves every 10 ms: 1.25 % of a core of the 1.5-1.9 % the
demo server then used (CPU per thread, 2026-11-26); it now shares the plant's deadline ticker (`simulator/ticker.py`).
"""
    print(body)
    write_section(HEADING, body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
