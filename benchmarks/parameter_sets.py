"""Parameter sets at scale: a 5,000-parameter set imported (JSON, CSV, DCF; every value checked against the
profile), stored, loaded and compared (set vs set with 5 % differences). Target (issue 9): import and compare
each under one second on this machine.

The profile is the 8400 motec's with its parameter list replaced by 2,500 codes x 2 subcodes of mixed types
(U16, S32 with factor 100, U8 selection lists), so the checks are the real ones. Prints a table; ``--write``
puts it into the ``## Parameter sets`` section of ``benchmarks/RESULTS.md``.

    .venv/bin/python benchmarks/parameter_sets.py [--write]
"""

from __future__ import annotations

import json
import os
import platform
import re
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.profile import Profile
from drivebench.services.sets import set_formats
from drivebench.services.sets.parameter_sets import ParameterSetStore, compare, set_source
from drivebench.services.storage import database

COUNT = 5000
ROUNDS = 5
RESULTS = REPO_ROOT / "benchmarks" / "RESULTS.md"


def big_profile() -> Profile:
    document = json.loads((REPO_ROOT / "device_profiles" / "lenze-8400-motec-canopen.json").read_text())
    parameters: list[dict[str, Any]] = []
    for code in range(1, COUNT // 2 + 1):
        for sub in (1, 2):
            kind = (code + sub) % 3
            entry: dict[str, Any] = {"code": f"C{code:05d}", "subcode": sub, "name": f"Bench parameter {code}",
                                     "subcode_name": f"Channel {sub}", "access": "rw", "group": f"Group {code % 20}"}
            if kind == 0:
                entry.update(data_type="UNSIGNED16", unit="ms", min=0, max=60000, default=code % 60000)
            elif kind == 1:
                entry.update(data_type="INTEGER32", unit="A", factor=100, min=-1000.0, max=1000.0,
                             default=round((code % 1000) / 10, 2))
            else:
                entry.update(data_type="UNSIGNED8", selection={"0": "off", "1": "on", "2": "auto"}, default=code % 3)
            parameters.append(entry)
    document.update(id="bench-5000", parameters=parameters, objects=[])
    return Profile.model_validate(document)


def timed(work: Callable[[], Any]) -> tuple[float, Any]:
    """Best of ROUNDS wall-clock seconds, and the last result."""
    best = float("inf")
    result = None
    for _ in range(ROUNDS):
        start = time.perf_counter()
        result = work()
        best = min(best, time.perf_counter() - start)
    return best, result


def main() -> list[tuple[str, str]]:
    profile = big_profile()
    lookup = {profile.id: profile}.__getitem__
    folder = Path(tempfile.mkdtemp(prefix="bench-sets-"))
    url = f"sqlite:///{folder / 'sets.db'}"
    database.upgrade_to_head(url)
    store = ParameterSetStore(url)
    defaults = set_formats.import_csv(
        "code,name,value,unit\n" + "\n".join(f"{p.code}/{p.subcode},,{p.default},"
                                             for p in profile.parameters),
        lookup, profile_id=profile.id).values
    first = store.create("bench", profile, defaults, user="bench")
    rows: list[tuple[str, str]] = []

    for fmt in set_formats.FORMATS:
        text, _ = set_formats.export(fmt, first, profile)
        seconds, imported = timed(lambda fmt=fmt, text=text: set_formats.import_any(  # type: ignore[misc]
            text.encode(), f"bench.{fmt}", lookup, profile_id=profile.id))
        assert imported.values == first.values, fmt
        export_s, _ = timed(lambda fmt=fmt: set_formats.export(fmt, first, profile))  # type: ignore[misc]
        rows.append((f"Import {COUNT:,} values from {fmt.upper()} ({len(text) // 1024} KiB, every value checked)",
                     f"{seconds * 1000:.0f} ms"))
        rows.append((f"Export {COUNT:,} values as {fmt.upper()}", f"{export_s * 1000:.0f} ms"))

    store_s, stored = timed(lambda: store.create("bench copy", profile, defaults, user="bench"))
    load_s, loaded = timed(lambda: store.get(stored.info.id))
    rows.append((f"Store a {COUNT:,}-value set (one transaction)", f"{store_s * 1000:.0f} ms"))
    rows.append((f"Load a {COUNT:,}-value set", f"{load_s * 1000:.0f} ms"))

    changed = dict(loaded.values)
    for n, ref in enumerate(list(changed)):
        if n % 20 == 0 and isinstance(changed[ref], int):
            changed[ref] = int(changed[ref]) + 1 if changed[ref] != 2 else 1
    other = store.create("bench changed", profile, changed, user="bench")
    compare_s, result = timed(lambda: compare(set_source(loaded, profile), set_source(other, profile)))
    filtered_s, _ = timed(lambda: compare(set_source(loaded, profile), set_source(other, profile), query="channel 2"))
    rows.append((f"Compare two {COUNT:,}-value sets ({result.total_differences} differences, scaled with units)",
                 f"{compare_s * 1000:.0f} ms"))
    rows.append(("Compare with a filter ('channel 2')", f"{filtered_s * 1000:.0f} ms"))
    import_json_ms = max(float(v.split()[0]) for k, v in rows if k.startswith("Import"))
    verdict = "met" if import_json_ms < 1000 and compare_s < 1 else "NOT met"
    rows.append(("Target: import and compare of 5,000 parameters each under 1 s", verdict))
    database.dispose(url)
    return rows


def section(rows: list[tuple[str, str]]) -> str:
    load = os.getloadavg()[0]
    lines = ["## Parameter sets", "", "Written by `benchmarks/parameter_sets.py` (best of "
             f"{ROUNDS} rounds, wall clock). A synthetic profile with {COUNT:,} parameters (U16 ms, S32 A with "
             "factor 100, U8 selection lists); SQLite database in a temporary folder. "
             f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
             f"load average {load:.1f} (shared).", "", "| Figure | Value |", "|---|---|"]
    lines += [f"| {name} | {value} |" for name, value in rows]
    return "\n".join(lines) + "\n"


def write(text: str) -> None:
    current = RESULTS.read_text()
    pattern = re.compile(r"^## Parameter sets\n.*?(?=^## |\Z)", re.DOTALL | re.MULTILINE)
    if pattern.search(current):
        updated = pattern.sub(lambda _: text + "\n", current)
    else:
        updated = current.rstrip("\n") + "\n\n" + text
    RESULTS.write_text(updated)


if __name__ == "__main__":
    table = section(main())
    print(table)
    if "--write" in sys.argv:
        write(table)
