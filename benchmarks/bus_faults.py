"""Figures for the bus-level faults (README 'Reliability'): how fast a fault is reported and how fast it heals.

Runs the real app on the demo plant (virtual bus, 0 ms latency) and prints:
- adapter unplugged: time until a request fails in words, time from plug-in to a working session;
- bus-off: how long a read-all of node 5 takes to fail, against what one-by-one timeouts would take;
- babbling node: bus load reached, time until the monitor names it, /api/health latency meanwhile.

    .venv/bin/python benchmarks/bus_faults.py
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import can
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.web.app import create_app

DEMO_PLANT = REPO_ROOT / "plants" / "demo.json"
SESSION = "/api/sessions/demo-plant"


def until(check: Callable[[], Any], timeout_s: float = 30.0) -> float:
    """Seconds until ``check()`` is true."""
    start = time.perf_counter()
    while time.perf_counter() - start < timeout_s:
        if check():
            return time.perf_counter() - start
        time.sleep(0.005)
    raise TimeoutError("condition not reached")


def main() -> None:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:bench-faults-{time.time_ns()}@500000", latency="0ms")
    with TestClient(app) as client:
        state = app.state.drivebench
        session = state.manager.get("demo-plant")
        adapter = session.network.bus.adapter
        read = lambda: client.get(f"{SESSION}/nodes/5/parameters/0x1000")  # noqa: E731

        read()  # warm up (the first read loads the node's catalogue)
        adapter.unplug()
        started = time.perf_counter()
        failed = read()
        fail_ms = (time.perf_counter() - started) * 1000
        time.sleep(1.0)
        adapter.plug_in()
        heal_s = until(lambda: read().status_code == 200)
        print(f"adapter unplugged: request fails in {fail_ms:.0f} ms ({failed.status_code}: {failed.json()['detail']})")
        print(f"adapter back: session works again {heal_s:.2f} s after plug-in "
              f"(back-off 0.2 s doubling to 5 s; {session.network.bus.link.reconnects} reconnect)")

        adapter.report(can.BusState.ERROR)
        started = time.perf_counter()
        job = client.post(f"{SESSION}/nodes/5/read-all").json()
        until(lambda: client.get(f"/api/jobs/{job['id']}").json()["state"] != "running")
        busoff_ms = (time.perf_counter() - started) * 1000
        total = client.get(f"/api/jobs/{job['id']}").json()["progress"]["total"]
        one_by_one = total * 0.5 * 2 / 2  # 0.5 s timeout, 1 retry, 2 SDO channels
        print(f"bus-off: read-all of {total} parameters fails in {busoff_ms:.0f} ms "
              f"(one-by-one timeouts would take ~{one_by_one:.0f} s)")
        adapter.report(can.BusState.ACTIVE)

        plant = state.plants["demo-plant"]
        client.get(f"{SESSION}/monitor?trace=0")
        babbler = plant.start_babbler(0x001)
        started = time.perf_counter()
        named_s = until(lambda: client.get(f"{SESSION}/monitor?trace=0").json()["flood"] is not None)
        latencies = []
        for _ in range(20):
            t0 = time.perf_counter()
            client.get("/api/health")
            latencies.append((time.perf_counter() - t0) * 1000)
            time.sleep(0.05)
        time.sleep(1.2)
        snapshot = client.get(f"{SESSION}/monitor?trace=0").json()
        starved = read()
        plant.stop_babbler()
        healed_s = until(lambda: read().status_code == 200)
        print(f"babbler 0x001: {babbler.frames_per_s:.0f} frames/s planned, load {snapshot['load']['percent']:.1f} % "
              f"(peak {snapshot['load']['peak_percent']:.1f} %), named after {named_s:.1f} s; "
              f"/api/health p50 {statistics.median(latencies):.1f} ms, max {max(latencies):.1f} ms; "
              f"SDO to node 5 meanwhile: {starved.status_code}; works again {healed_s:.2f} s after it stops")


if __name__ == "__main__":
    main()
