"""Ingest rate of the monitor's counting pipeline on one core, replaying a recorded mixed trace.

The trace (see ``_monitor_results.mixed_trace``) is recorded to a candump ``.log`` file by the monitor's own
recorder path (python-can writer), read back with ``can.LogReader`` and fed to ``Monitor.on_message_received`` in
one thread as fast as it goes (what the python-can notifier thread does with each frame). Target: >= 20,000
frames/s with no frame lost in the counts.
"""

from __future__ import annotations

import asyncio
import gc
import os
import sys
import tempfile
import time
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _monitor_results import machine, mixed_trace, write_subsection

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.monitoring.monitor import Monitor
from drivebench.services.session_manager import SessionManager

FRAMES = 200_000
ROUNDS = 3


def main() -> None:
    manager = SessionManager(ProfileRegistry())
    session = asyncio.run(manager.open("virtual:bench-ingest@500000", "bench"))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mixed.log"
        writer = can.CanutilsLogWriter(path, channel="can0")
        for msg in mixed_trace(FRAMES):
            writer.on_message_received(msg)
        writer.stop()
        replay = list(can.LogReader(path))
    expected_frames = sum(1 for m in replay if not m.is_error_frame)
    expected_errors = len(replay) - expected_frames
    rates, cpu_rates = [], []
    for _ in range(ROUNDS):
        monitor = Monitor(session)  # not attached to the bus: only the replay feeds it
        gc.collect()
        started, cpu_started = time.perf_counter(), time.thread_time()
        for msg in replay:
            monitor.on_message_received(msg)
        elapsed, cpu = time.perf_counter() - started, time.thread_time() - cpu_started
        rates.append(len(replay) / elapsed)
        cpu_rates.append(len(replay) / cpu)
        snap = monitor.snapshot()
        counted = sum(row["total"] for row in snap["cob_ids"])
        assert snap["totals"]["frames"] == expected_frames == counted, "frames lost in the counts"
        assert snap["totals"]["errors"] == expected_errors
        assert sum(row["total"] for row in snap["services"]) == expected_frames
    session.close()
    best, worst = max(rates), min(rates)
    cpu_best, cpu_worst = max(cpu_rates), min(cpu_rates)
    load = os.getloadavg()[0]
    print(f"replayed {len(replay)} frames x {ROUNDS}: wall {worst:,.0f} .. {best:,.0f} frames/s, one core's CPU time "
          f"{cpu_worst:,.0f} .. {cpu_best:,.0f} frames/s ({1e6 / cpu_best:.1f} us/frame); load average {load:.1f}; "
          f"counts exact ({expected_frames} frames, {expected_errors} error frames)")
    verdict = "met" if cpu_worst >= 20_000 else "NOT met"
    rows = [
        ("Ingest rate per CPU second of the one thread (slowest / fastest round)",
         f"{cpu_worst:,.0f} / {cpu_best:,.0f} frames/s"),
        ("Ingest rate, wall clock (slowest / fastest round)",
         f"{worst:,.0f} / {best:,.0f} frames/s (load average {load:.1f} on the shared machine)"),
        ("Cost per frame (fastest round, CPU)",
         f"{1e6 / cpu_best:.1f} µs (exact bit count with stuff bits, counters, trace ring, SDO context)"),
        ("Frames lost in the counts",
         f"0 (total = sum per COB-ID = sum per service = {expected_frames:,}; {expected_errors} error frames)"),
        ("Target >= 20,000 frames/s on one core", verdict),
    ]
    table = "\n".join(f"| {name} | {value} |" for name, value in rows)
    write_subsection("ingest (`benchmarks/monitor_ingest.py`)", f"""
Replay of a recorded mixed trace ({len(replay):,} frames: PDOs with changing data 60 %, SDO pairs, heartbeats,
SYNC, EMCY, NMT, LSS, 29-bit, error frames; candump `.log` read with `can.LogReader`) into
`Monitor.on_message_received` on one thread, {ROUNDS} rounds. Machine: {machine()}.

| Figure | Value |
|---|---|
{table}
""")

if __name__ == "__main__":
    main()
