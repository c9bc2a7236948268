"""Parameterisation speed (issue 4), printed and written to RESULTS.md under '## Parameters'.

(a) expedited SDO reads/s through the service layer vs raw canopen on the same bus, same run (target ratio >= 0.8)
(b) read-all of 10 simulated nodes x 300 parameters, 30 ms simulator latency, vs one-at-a-time sequential (>= 10x)
(c) memory of the server (process RSS) with 10 nodes fully read
(d) /api/health latency during a read-all of every node (target < 50 ms)

The server runs as `drivebench serve --plant` in a child process with the simulated plant; (a) and the
sequential baseline run the service layer in this process.
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
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "backend"))

from drivebench.device.profiles.catalog import Catalog  # noqa: E402
from drivebench.device.profiles.loader import ProfileRegistry  # noqa: E402
from drivebench.device.profiles.profile import Access, Parameter, Profile  # noqa: E402
from drivebench.errors import DriveBenchError  # noqa: E402
from drivebench.protocol.datatypes import DataType  # noqa: E402
from drivebench.services.params import lookup, reads  # noqa: E402
from drivebench.services.session_manager import SessionManager  # noqa: E402
from drivebench.simulator.plant import Plant, PlantFile  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
HEADING = "## Parameters"
NODES = 10
PER_NODE = 300
LATENCY = "30ms"
BASE_PROFILE = "lenze-8400-motec-canopen"


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def bench_profile(registry: ProfileRegistry) -> Profile:
    """The 8400 motec profile filled up with extra U16 codes to exactly 300 readable items."""
    base = registry.get(BASE_PROFILE)
    catalog = Catalog(base)
    readable = sum(1 for item in catalog.items if item.entry.access.readable)
    extra: list[Parameter] = []
    number = 1000
    while readable + len(extra) < PER_NODE:
        number += 1
        code = f"C{number:05d}"
        if any(p.code == code for p in base.parameters):
            continue
        extra.append(Parameter(code=code, name=f"Benchmark value {number}", data_type=DataType.UNSIGNED16,
                               access=Access.RW, default=number % 997, group="Benchmark"))
    return base.model_copy(update={"id": "bench-8400-300", "parameters": [*base.parameters, *extra],
                                   "groups": [*base.groups, "Benchmark"]})


# --- (a) -----------------------------------------------------------------------------------------------------
ROUNDS = 60


async def expedited_ratio(registry: ProfileRegistry, rounds: int = ROUNDS, per_round: int = 100) -> dict[str, float]:
    """Reads of C00061 (INTEGER32, expedited) in short interleaved rounds, alternating which path goes first, so
    the load of a shared machine hits both alike; the ratio is the median of the rounds' ratios."""
    plant_file = PlantFile.model_validate({"name": "a", "nodes": [{"node_id": 5, "profile": BASE_PROFILE}]})
    plant = Plant(plant_file, registry.get, bus="virtual:bench-param-a@500000", latency="0ms").start()
    manager = SessionManager(registry)
    session = await manager.open(plant.spec, "a")
    session.add_node(5, BASE_PROFILE)
    raw_sdo = session.client(5).remote.sdo  # the canopen SdoClient itself

    def raw_round() -> float:
        started = time.perf_counter()
        for _ in range(per_round):
            raw_sdo.upload(0x5FC2, 0)
        return time.perf_counter() - started

    async def threaded_round() -> float:  # canopen as a server must call it: off the event loop
        started = time.perf_counter()
        for _ in range(per_round):
            await asyncio.to_thread(raw_sdo.upload, 0x5FC2, 0)
        return time.perf_counter() - started

    async def service_round() -> float:
        started = time.perf_counter()
        for _ in range(per_round):
            await reads.read(session, 5, "C00061")
        return time.perf_counter() - started

    raw_times: list[float] = []
    threaded_times: list[float] = []
    service_times: list[float] = []
    try:
        for _ in range(3):  # warm up every path
            raw_round()
            await threaded_round()
            await service_round()
        for number in range(rounds):
            if number % 2:
                service_times.append(await service_round())
                raw_times.append(raw_round())
            else:
                raw_times.append(raw_round())
                service_times.append(await service_round())
            threaded_times.append(await threaded_round())
    finally:
        await manager.close_all()
        plant.stop()
    load = os.getloadavg()[0]
    ratios = sorted(raw / service for raw, service in zip(raw_times, service_times, strict=True))
    return {"raw_per_s": per_round / statistics.median(raw_times),
            "threaded_per_s": per_round / statistics.median(threaded_times),
            "service_per_s": per_round / statistics.median(service_times),
            "ratio": statistics.median(ratios), "ratio_q1": ratios[len(ratios) // 4],
            "ratio_q3": ratios[3 * len(ratios) // 4],
            "ratio_threaded": statistics.median(threaded_times) / statistics.median(service_times), "load": load}


# --- (b), (c), (d) ---------------------------------------------------------------------------------------------
class _Profiles:
    """Profile source for the in-process baseline: the registry plus the benchmark profile."""

    def __init__(self, registry: ProfileRegistry, extra: Profile) -> None:
        self.registry = registry
        self.extra = extra

    def get(self, profile_id: str) -> Profile:
        return self.extra if profile_id == self.extra.id else self.registry.get(profile_id)

    def find_by_identity(self, vendor_id: int | None, product_code: int | None) -> Profile | None:
        return None


async def sequential_rate(registry: ProfileRegistry, profile: Profile) -> dict[str, Any]:
    """One-at-a-time: one node's 300 parameters one after the other through the service layer (SDO1)."""
    profiles = _Profiles(registry, profile)
    plant_file = PlantFile.model_validate({"name": "seq", "nodes": [
        {"node_id": 1, "profile": profile.id, "latency": LATENCY}]})
    plant = Plant(plant_file, profiles.get, bus="virtual:bench-param-seq@500000").start()
    manager = SessionManager(profiles)
    session = await manager.open(plant.spec, "seq")
    session.add_node(1, profile.id)
    items = lookup.readable_items(session.node(1))
    assert len(items) == PER_NODE, len(items)
    failures: list[str] = []
    try:
        started = time.perf_counter()
        for item in items:
            try:
                await reads.read(session, 1, item.ref)
            except DriveBenchError as exc:
                failures.append(f"{item.ref}: {exc.detail}")
        elapsed = time.perf_counter() - started
    finally:
        await manager.close_all()
        plant.stop()
    return {"sequential_per_s": PER_NODE / elapsed, "sequential_all_s": elapsed * NODES,
            "sequential_failed": failures}


def _proc_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def server_figures(profile: Profile, workdir: Path) -> dict[str, Any]:
    """The real server (`drivebench serve --plant`) in its own process; read-all of every node over HTTP."""
    user_dir = workdir / "profiles"
    user_dir.mkdir()
    (user_dir / f"{profile.id}.json").write_text(profile.model_dump_json(), encoding="utf-8")
    plant_path = workdir / "plant.json"
    plant_path.write_text(json.dumps({"name": "Bench plant", "bus": "virtual:bench-param-b@500000", "nodes": [
        {"node_id": n, "profile": profile.id, "latency": LATENCY} for n in range(1, NODES + 1)]}))
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    env = {**os.environ, "DRIVEBENCH_USER_PROFILES_DIR": str(user_dir),
           "DRIVEBENCH_DATABASE_URL": f"sqlite:///{workdir / 'bench.db'}"}
    server = subprocess.Popen([sys.executable, "-m", "drivebench.cli", "serve", "--plant", str(plant_path),
                               "--port", str(port)], env=env, cwd=ROOT)
    figures: dict[str, Any] = {}
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if http.get("/api/health").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline or server.poll() is not None:
                    raise RuntimeError("the server did not start")
                time.sleep(0.2)
            figures["rss_start_mb"] = _proc_rss_mb(server.pid)
            started = time.perf_counter()
            job = http.post("/api/sessions/bench-plant/read-all", json={}).json()
            health_ms: list[float] = []
            state = "running"
            while state == "running":
                t0 = time.perf_counter()
                assert http.get("/api/health").status_code == 200
                health_ms.append((time.perf_counter() - t0) * 1000)
                time.sleep(0.02)
                if len(health_ms) % 10 == 0:
                    state = http.get(f"/api/jobs/{job['id']}").json()["state"]
            final = http.get(f"/api/jobs/{job['id']}").json()
            figures.update(
                parallel_s=final["progress"]["elapsed_s"], parallel_wall_s=time.perf_counter() - started,
                job_state=final["state"], done=final["progress"]["done"], failed=final["progress"]["failed"],
                read=sum(len(v) for v in final["result"]["values"].values()), notes=final["notes"],
                health_median_ms=statistics.median(health_ms),
                health_p95_ms=sorted(health_ms)[max(int(len(health_ms) * 0.95) - 1, 0)],
                health_max_ms=max(health_ms), health_samples=len(health_ms),
                rss_read_mb=_proc_rss_mb(server.pid))
            listed = http.get("/api/sessions/bench-plant/nodes/1/parameters").json()["parameters"]
            figures["values_held"] = NODES * sum(1 for p in listed if p["last"] is not None)
    finally:
        server.terminate()
        server.wait(timeout=20)
    return figures


def write_results(a: dict[str, float], b: dict[str, Any]) -> str:
    lines = [
        HEADING, "",
        f"`benchmarks/param_speed.py`, {time.strftime('%Y-%m-%d %H:%M')} on {platform.node()} "
        f"({platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores, load average "
        f"{a['load']:.1f} during (a)); simulator on a python-can virtual bus in the same process.", "",
        "| Figure | Measured | Target |", "|---|---|---|",
        f"| (a) expedited SDO reads/s, raw canopen `SdoClient.upload` | {a['raw_per_s']:.0f}/s | |",
        f"| (a) expedited SDO reads/s, service layer `reads.read` (scaled) | {a['service_per_s']:.0f}/s | |",
        f"| (a) expedited SDO reads/s, raw canopen called from a worker thread (as a server must) | "
        f"{a['threaded_per_s']:.0f}/s | |",
        f"| (a) ratio service / raw canopen (median of {ROUNDS} interleaved rounds; quartiles {a['ratio_q1']:.2f}"
        f" ... {a['ratio_q3']:.2f}) | **{a['ratio']:.2f}** | >= 0.8 |",
        f"| (a) ratio service / raw canopen in a worker thread | {a['ratio_threaded']:.2f} | |",
        f"| (b) one-at-a-time sequential ({PER_NODE} reads measured, {LATENCY} latency) | "
        f"{b['sequential_per_s']:.1f}/s -> {b['sequential_all_s']:.1f} s for {NODES * PER_NODE} | |",
        f"| (b) read-all job, {NODES} nodes x {PER_NODE} parameters, SDO1+SDO2 per node | "
        f"{b['parallel_s']:.2f} s ({b['read']} read, {b['failed']} failed, {b['job_state']}) | |",
        f"| (b) speed-up | **{b['speedup']:.1f}x** | >= 10x |",
        f"| (c) server process RSS at start / with {NODES} nodes fully read | {b['rss_start_mb']:.0f} MB / "
        f"{b['rss_read_mb']:.0f} MB ({b['values_held']} values held) | |",
        f"| (d) `/api/health` during the read-all: median / p95 / max ({b['health_samples']} requests) | "
        f"{b['health_median_ms']:.1f} / {b['health_p95_ms']:.1f} / {b['health_max_ms']:.1f} ms | < 50 ms |",
        "",
        "The sequential figure reads one node's 300 parameters one after the other through the same service and "
        "scales the measured time to 3000 reads (a full sequential run would take minutes). The server is "
        "`drivebench serve --plant` in its own process (its RSS includes the simulated plant it runs); "
        "`/api/health` is polled from this process every 20 ms while the job runs.", "",
        "(a) is one request at a time on one SDO channel, so it measures per-read overhead on top of the same wire "
        "round trip. " + ("Target met" if a["ratio"] >= 0.8 else "Target NOT met") + f" in this run ({a['ratio']:.2f})."
        " Before the 2026-11-23 profiling the ratio was 0.65 ... 0.76 (0.71 in the last table, 0.76 at load 2.5). "
        "cProfile and per-read timestamps showed where the service lost to canopen: (1) the response resolved an "
        "asyncio future from the reader thread's `call_soon_threadsafe`, which wakes the loop once and then needs a "
        "second loop iteration to resume the awaiting task (about 17 us here); (2) the loop's self-pipe is read "
        "twice per wake-up, each read releasing the GIL the bus threads are waiting for; (3) a timer per read; "
        "(4) about 10 us of lookup, decoding, scaling and formatting per read. Now the awaited answer is a "
        "duck-typed future that runs the task's step inside the wake-up, the reader thread wakes the loop through "
        "an eventfd read once, one watchdog timer per SDO channel re-arms itself, and each item's request, decoder "
        "and name are worked out once (scaling and formatting again only when the raw value changes): 2 us instead "
        "of 10. Per-read medians are now within a few microseconds of raw canopen; what spread remains comes from "
        "scheduling on the shared 2-core machine (quartiles above). The raw figure blocks the calling thread, "
        "which a server's event loop must not do; canopen called from a worker thread, as a server would have "
        "to, is the third row.", "",
        "(d) " + ("met" if b["health_max_ms"] < 50 else
                  f"NOT met at the maximum ({b['health_max_ms']:.0f} ms): single requests meet a CPU shared with the "
                  "server's 10 simulated nodes and, on this machine, other engineers' jobs (load average above); "
                  "the median and p95 stay well under 50 ms") + ".", "",
    ]
    section = "\n".join(lines)
    text = RESULTS.read_text(encoding="utf-8") if RESULTS.exists() else "# Benchmark results\n"
    start = text.find(f"\n{HEADING}\n")
    if start >= 0:
        start += 1
        end = text.find("\n## ", start + len(HEADING))
        text = text[:start] + section + ("\n" + text[end + 1:] if end >= 0 else "")
    else:
        text = text.rstrip("\n") + "\n\n" + section
    RESULTS.write_text(text, encoding="utf-8")
    return section


async def main() -> None:
    registry = ProfileRegistry()
    a = await expedited_ratio(registry)
    print(f"(a) raw canopen {a['raw_per_s']:.0f}/s, service {a['service_per_s']:.0f}/s, ratio {a['ratio']:.2f} "
          f"(quartiles {a['ratio_q1']:.2f} ... {a['ratio_q3']:.2f}); canopen in a worker thread "
          f"{a['threaded_per_s']:.0f}/s")
    profile = bench_profile(registry)
    b = await sequential_rate(registry, profile)
    with tempfile.TemporaryDirectory() as workdir:
        b.update(server_figures(profile, Path(workdir)))
    b["speedup"] = b["sequential_all_s"] / b["parallel_s"]
    print(f"(b) sequential {b['sequential_all_s']:.1f} s (est.), read-all {b['parallel_s']:.2f} s, "
          f"speed-up {b['speedup']:.1f}x, {b['read']} read, {b['failed']} failed")
    if b["sequential_failed"]:
        print("sequential failures:", b["sequential_failed"][:5])
    print(f"(c) server RSS {b['rss_start_mb']:.0f} MB -> {b['rss_read_mb']:.0f} MB")
    print(f"(d) /api/health median {b['health_median_ms']:.1f} ms, p95 {b['health_p95_ms']:.1f} ms, "
          f"max {b['health_max_ms']:.1f} ms")
    print(write_results(a, b))


if __name__ == "__main__":
    asyncio.run(main())
