"""Stored scope recordings: the samples packed in one binary value, the rest as JSON (table ``scope_recording``).

Packed: the sample numbers (int64), the times in seconds and each channel's values (float64; NaN where the node
sent nothing), one array after the other, little-endian. Packing and unpacking are ``array`` copies, so 8 channels x
100,000 samples are written and read back well under a second (``benchmarks/scope_store.py``).
"""

from __future__ import annotations

import contextlib
import math
import sys
from array import array
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from sqlalchemy import select

from drivebench.errors import NotFound
from drivebench.i18n import Text, _, shown
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import DownloadRow, ScopeRecordingRow

NAN = math.nan


@dataclass
class Columns:
    """A recording's samples by column: ``values[c][i]`` is channel ``c`` at sample ``i`` (None: nothing sent)."""

    samples: list[int] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    values: list[list[float | None]] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.samples)


def pack(columns: Columns) -> bytes:
    count = len(columns)
    parts: list[array[Any]] = [array("q", columns.samples), array("d", columns.times)]
    for channel in columns.values:
        if len(channel) != count:
            raise ValueError("every channel holds one value per sample")
        parts.append(array("d", [NAN if value is None else value for value in channel]))
    if sys.byteorder != "little":
        for part in parts:
            part.byteswap()
    return b"".join(part.tobytes() for part in parts)


def unpack(data: bytes, count: int, channels: int) -> Columns:
    samples, times = array("q"), array("d")
    step = count * 8
    samples.frombytes(data[:step])
    times.frombytes(data[step:2 * step])
    values = []
    for channel in range(channels):
        column = array("d")
        column.frombytes(data[(2 + channel) * step:(3 + channel) * step])
        if sys.byteorder != "little":
            column.byteswap()
        values.append([None if value != value else value for value in column])  # NaN != NaN
    if sys.byteorder != "little":
        samples.byteswap()
        times.byteswap()
    return Columns(samples.tolist(), times.tolist(), values)


def marker(time_s: float, node: int | None, kind: str, text: str) -> dict[str, Any]:
    """A marker as stored: ``text`` in English (as every stored row had it), and a
    :class:`~drivebench.i18n.Text`'s template and values under ``text_saved`` so that each reader gets it in their
    language (:func:`shown_marker`)."""
    stored: dict[str, Any] = {"time_s": round(time_s, 6), "node": node, "kind": kind, "text": str(text)}
    if isinstance(text, Text):
        stored["text_saved"] = text.saved()
    return stored


def shown_marker(stored: dict[str, Any]) -> dict[str, Any]:
    """A stored marker as a reader gets it: its text in the current language where it was kept as a Text; a
    marker stored before (plain text only) as it is."""
    saved = stored.get("text_saved")
    found = {key: value for key, value in stored.items() if key != "text_saved"}
    if isinstance(saved, dict):
        with contextlib.suppress(KeyError, ValueError, IndexError, AssertionError):  # damaged: its English text
            found["text"] = shown(Text.loaded(saved))
    return found


@dataclass
class Recording:
    """A recording as stored (``id`` None until it is)."""

    name: str
    session_id: str
    created_by: str
    source: str
    period_s: float
    channels: list[dict[str, Any]]
    trigger: dict[str, Any]
    markers: list[dict[str, Any]]
    nodes: dict[str, Any]
    columns: Columns
    id: int | None = None
    created: datetime | None = None

    def summary(self) -> dict[str, Any]:
        return {"id": self.id, "name": self.name, "session_id": self.session_id, "created_by": self.created_by,
                "created": self.created.isoformat() if self.created else None, "source": self.source,
                "period_s": self.period_s, "count": len(self.columns), "channels": self.channels}

    def as_json(self) -> dict[str, Any]:
        """In the current language (the markers' texts)."""
        return {**self.summary(), "trigger": self.trigger, "markers": [shown_marker(m) for m in self.markers],
                "nodes": self.nodes,
                "samples": self.columns.samples, "times": self.columns.times, "values": self.columns.values}


def save(recording: Recording) -> int:
    with transaction() as db:
        row = ScopeRecordingRow(
            name=recording.name[:200], session_id=recording.session_id, created_by=recording.created_by,
            source=recording.source, period_s=recording.period_s, channels=recording.channels,
            trigger=recording.trigger, markers=recording.markers, nodes=recording.nodes,
            count=len(recording.columns), samples=pack(recording.columns))
        db.add(row)
        db.flush()
        recording.id, recording.created = row.id, row.created
        return row.id


def _recording(row: ScopeRecordingRow, columns: Columns) -> Recording:
    return Recording(row.name, row.session_id, row.created_by, row.source, row.period_s, row.channels, row.trigger,
                     row.markers, row.nodes, columns, row.id, row.created)


def load(recording_id: int) -> Recording:
    with transaction() as db:
        row = db.get(ScopeRecordingRow, recording_id)
        if row is None:
            raise NotFound(_("There is no scope recording {id}.").format(id=recording_id))
        return _recording(row, unpack(row.samples, row.count, len(row.channels)))


def listing(limit: int = 200) -> list[dict[str, Any]]:
    """The newest recordings first, without their samples."""
    with transaction() as db:
        columns = [c for c in ScopeRecordingRow.__table__.columns if c.name != "samples"]
        rows = db.execute(select(*columns).order_by(ScopeRecordingRow.id.desc()).limit(limit)).all()
    return [{"id": r.id, "name": r.name, "session_id": r.session_id, "created_by": r.created_by,
             "created": r.created.isoformat(), "source": r.source, "period_s": r.period_s, "count": r.count,
             "channels": r.channels} for r in rows]


def remove(recording_id: int) -> None:
    with transaction() as db:
        row = db.get(ScopeRecordingRow, recording_id)
        if row is None:
            raise NotFound(_("There is no scope recording {id}.").format(id=recording_id))
        db.delete(row)


def last_downloads(session_id: str, node_ids: list[int]) -> dict[int, tuple[int | None, int | None]]:
    """Per node: the parameter set (id, version) last downloaded to it in this session, if any (whatever its
    outcome: the recording shows what was tried last)."""
    found: dict[int, tuple[int | None, int | None]] = {}
    with transaction() as db:
        for node_id in node_ids:
            row = db.execute(select(DownloadRow.set_id, DownloadRow.set_version).where(
                DownloadRow.session_id == session_id, DownloadRow.node_id == node_id,
                DownloadRow.kind == "download").order_by(DownloadRow.id.desc()).limit(1)).first()
            if row is not None:
                found[node_id] = (row.set_id, row.set_version)
    return found
