"""Start-up with 200 stored profile uploads (issue 33: 17.6 s before ``/api/health`` answered, every stored upload
parsed in the app's lifespan): prints the figures and puts them into the ``## Start-up with stored uploads`` section
of ``benchmarks/RESULTS.md``.

Both starts run in the same process on the same folder: the first finds no parsed cache (``<folder>.parsed/``,
``device/profiles/parsed_cache.py``) and parses every file as before, the second takes the parsed files from it.
The ratio compares like with like.

    .venv/bin/python benchmarks/startup_uploads.py
"""

from __future__ import annotations

import os
import platform
import re
import tempfile
import time
from pathlib import Path

from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app

RESULTS = REPO_ROOT / "benchmarks" / "RESULTS.md"
UPLOADS = 200
SECTION = "## Start-up with stored uploads"
NOTE = ("Wall time on this shared machine is mostly the wait for a core (see the load average); the CPU seconds "
        "compare the work. The second start's CPU goes mostly to reading and validating the 200 cached profiles "
        "(cProfile, 2026-11-29); the first start's to the EDS import.")


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


def start(folder: Path) -> tuple[float, float, int]:
    """Wall and CPU seconds from building the app to the first answer of ``/api/health``, and the uploads listed."""
    settings.user_profiles_dir = folder
    began, cpu = time.perf_counter(), time.process_time()
    with TestClient(create_app(), base_url="http://127.0.0.1") as client:
        assert client.get("/api/health").status_code == 200
        seconds, cpu = time.perf_counter() - began, time.process_time() - cpu
        listed = sum(not p["builtin"] for p in client.get("/api/profiles").json())
    return seconds, cpu, listed


def main() -> list[tuple[str, str]]:
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "user-profiles"
        size = store_uploads(folder)
        cold, cold_cpu, listed_cold = start(folder)
        warm, warm_cpu, listed_warm = start(folder)
    return [
        (f"{UPLOADS} stored EDS uploads ({size / 1e6:.1f} MB, the shipped EDS files in turn)",
         f"{listed_cold} / {listed_warm} listed after the first / second start"),
        ("First start, nothing parsed before (parses every file, writes the parsed cache)",
         f"{cold:.1f} s wall, {cold_cpu:.1f} s CPU to /api/health"),
        ("Second start, the parsed cache beside the folder", f"{warm:.2f} s wall, {warm_cpu:.2f} s CPU to /api/health"),
        ("Ratio first / second (same run, same folder)", f"{cold / warm:.0f} x wall, {cold_cpu / warm_cpu:.0f} x CPU"),
    ]


def write_results(rows: list[tuple[str, str]]) -> None:
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
               f"Python {platform.python_version()}")
    table = "\n".join(["| Figure | Value |", "|---|---|", *(f"| {k} | {v} |" for k, v in rows)])
    section = (f"{SECTION}\n\nWritten by `benchmarks/startup_uploads.py` ({time.strftime('%Y-%m-%d')}, {machine}, "
               f"load average {os.getloadavg()[0]:.1f}). Issue 33: a restart with about 200 stored uploads took 17.6 s "
               "before `/api/health` answered.\n\n" + table + "\n\n" + NOTE + "\n")
    text = RESULTS.read_text(encoding="utf-8")
    if SECTION in text:
        head, rest = text.split(SECTION, 1)
        tail = rest[rest.find("\n## "):] if "\n## " in rest else "\n"
        text = head + section + tail
    else:
        text = text.rstrip("\n") + "\n\n" + section
    RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    figures = main()
    for name, value in figures:
        print(f"{name}: {value}")
    write_results(figures)
