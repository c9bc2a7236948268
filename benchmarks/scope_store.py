"""Scope recordings in the database (issue 31): 8 channels x 100,000 samples stored and read back (target: each
< 1 s), in a SQLite file (``--url`` for another database). Writes its line to RESULTS.md under "## Scope"."""

from __future__ import annotations

import argparse
import math
import re
import tempfile
import time
from pathlib import Path

from drivebench.config import settings
from drivebench.services.scope import store
from drivebench.services.storage import database

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
CHANNELS, SAMPLES = 8, 100_000


def run(url: str) -> tuple[float, float]:
    settings.database_url = url
    database.upgrade_to_head(url)
    values: list[list[float | None]] = [[math.sin(n / 50 + c) * 1500 for n in range(SAMPLES)]
                                        for c in range(CHANNELS)]
    columns = store.Columns(list(range(SAMPLES)), [n * 0.001 for n in range(SAMPLES)], values)
    recording = store.Recording("benchmark", "bench", "bench", "pdo", 0.001,
                                [{"node": 1, "ref": f"0x60{c:02X}", "label": str(c), "unit": None}
                                 for c in range(CHANNELS)], {}, [], {}, columns)
    started = time.perf_counter()
    recording_id = store.save(recording)
    stored = time.perf_counter() - started
    started = time.perf_counter()
    back = store.load(recording_id)
    loaded = time.perf_counter() - started
    assert back.columns == columns
    return stored, loaded


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--url", help="database URL (default: a new SQLite file)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        url = args.url or f"sqlite:///{Path(tmp) / 'scope.db'}"
        stored, loaded = run(url)
        database.dispose(url)
    line = (f"8 channels x 100,000 samples ({'SQLite' if url.startswith('sqlite') else url.split(':')[0]}): "
            f"stored in {stored:.3f} s, read back in {loaded:.3f} s (target < 1 s each)")
    print(line)
    text = RESULTS.read_text(encoding="utf-8") if RESULTS.exists() else "# Benchmark results\n"
    block = f"## Scope\n\nWritten by `benchmarks/scope_store.py`.\n\n- {line}\n"
    if "## Scope" in text:
        text = re.sub(r"## Scope\n.*?(?=^## |\Z)", block + "\n", text, flags=re.MULTILINE | re.DOTALL)
    else:
        text = text.rstrip("\n") + "\n\n" + block
    RESULTS.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
