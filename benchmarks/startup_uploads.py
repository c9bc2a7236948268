"""Start-up with 200 stored profile uploads (issue 33: 17.6 s before ``/api/health`` answered, every stored upload
parsed in the app's lifespan): prints the figures and puts them into the ``## Start-up with stored uploads`` section
of ``benchmarks/RESULTS.md``. The uploads now load in a worker thread after the server listens: each start is
measured to the first answer of ``/api/health`` and to its ``"profiles": {"state": "loaded"}`` (all uploads read).

Both starts run in the same process on the same folder: the first finds no parsed cache (``<folder>.parsed/``,
``device/profiles/parsed_cache.py``) and parses every file as before, the second takes the parsed files from it.
The ratio compares like with like.

    .venv/bin/python benchmarks/startup_uploads.py
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from _monitor_results import machine, write_section
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app

UPLOADS = 200
SECTION = "## Start-up with stored uploads"
NOTE = ("Wall time on this shared machine is mostly the wait for a core (see the load average); the CPU seconds "
        "compare the work (the process's, all threads). /api/health answers once the shipped profiles are read and "
        "the start has waited at most 0.5 s for the uploads; reading them goes on in a worker thread. The second "
        "start's loading CPU goes mostly to reading and validating the 200 cached profiles (cProfile, 2026-11-29); "
        "the first start's to the EDS import. The baseline runs first in the process and pays the lazy imports "
        "(database, templates); /api/health then waits for the same work with 200 uploads as with none.")


def store_uploads(folder: Path) -> int:
    """200 stored uploads: the shipped EDS files in turn, each under its own id (``ProfileId=up-NNN``)."""
    sources = sorted((REPO_ROOT / "device_profiles" / "eds").glob("*.eds"))
    folder.mkdir(parents=True)
    size = 0
    for n in range(UPLOADS):
        content = re.sub(rb"ProfileId=[^\r\n]*", f"ProfileId=up-{n:03d}".encode(),
                         sources[n % len(sources)].read_bytes(), count=1)
        (folder / f"up-{n:03d}.eds").write_bytes(content)
        size += len(content)
    return size


@dataclass(frozen=True)
class Start:
    health_s: float
    health_cpu: float
    loaded_s: float
    loaded_cpu: float
    listed: int
    loading_at_health: bool


def start(folder: Path) -> Start:
    """Wall and CPU seconds from building the app to the first answer of ``/api/health`` and to all uploads read."""
    settings.user_profiles_dir = folder
    began, cpu = time.perf_counter(), time.process_time()
    with TestClient(create_app(), base_url="http://127.0.0.1") as client:
        first = client.get("/api/health")
        assert first.status_code == 200
        health_s, health_cpu = time.perf_counter() - began, time.process_time() - cpu
        loading = first.json()["profiles"]["state"] == "loading"
        while client.get("/api/health").json()["profiles"]["state"] != "loaded":
            time.sleep(0.05)
        loaded_s, loaded_cpu = time.perf_counter() - began, time.process_time() - cpu
        listed = sum(not p["builtin"] for p in client.get("/api/profiles").json())
    return Start(health_s, health_cpu, loaded_s, loaded_cpu, listed, loading)


def main() -> list[tuple[str, str]]:
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "user-profiles"
        size = store_uploads(folder)
        empty = start(Path(scratch) / "no-uploads")  # the same start without any upload: what health waits for
        cold = start(folder)
        warm = start(folder)
    return [
        (f"{UPLOADS} stored EDS uploads ({size / 1e6:.1f} MB, the shipped EDS files in turn)",
         f"{cold.listed} / {warm.listed} listed after the first / second start"),
        ("Start with no stored uploads (the baseline): to /api/health",
         f"{empty.health_s:.2f} s wall, {empty.health_cpu:.2f} s CPU"),
        ("First start, nothing parsed before: to /api/health",
         f"{cold.health_s:.2f} s wall, {cold.health_cpu:.2f} s CPU"
         f" (uploads {'still loading' if cold.loading_at_health else 'already loaded'})"),
        ("First start: to all uploads loaded (parses every file, writes the parsed cache)",
         f"{cold.loaded_s:.1f} s wall, {cold.loaded_cpu:.1f} s CPU"),
        ("Second start, the parsed cache beside the folder: to /api/health",
         f"{warm.health_s:.2f} s wall, {warm.health_cpu:.2f} s CPU"
         f" (uploads {'still loading' if warm.loading_at_health else 'already loaded'})"),
        ("Second start: to all uploads loaded", f"{warm.loaded_s:.2f} s wall, {warm.loaded_cpu:.2f} s CPU"),
        ("Ratio first / second to all loaded (same run, same folder)",
         f"{cold.loaded_s / warm.loaded_s:.0f} x wall, {cold.loaded_cpu / warm.loaded_cpu:.0f} x CPU"),
    ]


def write_results(rows: list[tuple[str, str]]) -> None:
    table = "\n".join(["| Figure | Value |", "|---|---|", *(f"| {k} | {v} |" for k, v in rows)])
    body = (f"Written by `benchmarks/startup_uploads.py` ({time.strftime('%Y-%m-%d')}, {machine()}, "
            f"load average {os.getloadavg()[0]:.1f}). Issue 33: a restart with about 200 stored uploads took 17.6 s "
            "before `/api/health` answered.\n\n" + table + "\n\n" + NOTE + "\n")
    write_section(SECTION, body)


if __name__ == "__main__":
    figures = main()
    for name, value in figures:
        print(f"{name}: {value}")
    write_results(figures)
