"""A stored recording as a file other tools open: CSV (one row per sample, a column per channel with its unit) and
JSON (everything the recording holds)."""

from __future__ import annotations

import csv
import io
import json

from drivebench.services.scope.store import Recording


def _number(value: float | None) -> str:
    return "" if value is None else f"{value:.6g}"


def to_csv(recording: Recording) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    heads = [f"{c['label']} [{c['unit']}]" if c.get("unit") else str(c["label"]) for c in recording.channels]
    writer.writerow(["sample", "time_s", *heads])
    columns = recording.columns
    for row, sample in enumerate(columns.samples):
        writer.writerow([sample, f"{columns.times[row]:.6f}", *(_number(v[row]) for v in columns.values)])
    return out.getvalue()


def to_json(recording: Recording) -> str:
    return json.dumps(recording.as_json(), separators=(",", ":"), allow_nan=False)


def file_name(recording: Recording, suffix: str) -> str:
    return f"scope-{recording.id}.{suffix}"
