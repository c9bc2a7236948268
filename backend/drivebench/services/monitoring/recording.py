"""Recording a session's frames to a file other tools open: candump ``.log``, Vector ``.asc`` and ``.blf``, PEAK
``.trc``, python-can ``.csv`` (python-can's writers) and ``.pcapng`` with the SocketCAN link type (our writer, for
Wireshark's CANopen dissector).

The recorder's listener only queues the frame; a writer thread formats and writes, so a slow disk or the ASC
formatter never holds up the bus threads. Frames are written on the writer's default channel (can0 / channel 1):
a session is one bus, and python-can would otherwise turn trailing digits of the adapter's channel name into a
channel number (a virtual channel ``line-1700000000`` does not fit BLF's 16-bit channel field).
"""

from __future__ import annotations

import copy
import queue
import re
import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import can

from drivebench.config import settings
from drivebench.errors import Conflict, InvalidValue, NotFound
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session
from drivebench.transport.pcapng import PcapngWriter

FORMATS = {"pcapng": N_("pcapng, SocketCAN link type (.pcapng, Wireshark)"), "log": N_("candump log (.log)"),
           "asc": "Vector ASCII (.asc)", "blf": "Vector BLF (.blf)", "trc": N_("PEAK trace (.trc)"),
           "csv": "python-can CSV (.csv)"}
"""Format -> its name (:func:`format_names` in the reader's language)."""
MEDIA_TYPES = {"log": "text/plain", "asc": "text/plain", "blf": "application/octet-stream",
               "pcapng": "application/vnd.tcpdump.pcap", "trc": "text/plain", "csv": "text/csv"}
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*\.(log|asc|blf|pcapng|trc|csv)$")


def format_names() -> dict[str, str]:
    return {key: _(name) for key, name in FORMATS.items()}


def recordings_dir() -> Path:
    return settings.user_profiles_dir.parent / "recordings"


def open_writer(path: Path) -> can.Listener:
    if path.suffix == ".pcapng":
        return PcapngWriter(path)
    if path.suffix == ".log":
        return can.CanutilsLogWriter(path, channel="can0")
    if path.suffix == ".asc":
        return can.ASCWriter(path)
    if path.suffix == ".blf":
        return can.BLFWriter(path)
    if path.suffix == ".trc":
        return can.TRCWriter(path)
    if path.suffix == ".csv":
        return can.CSVWriter(path)
    raise unknown_format(path.suffix)


def unknown_format(fmt: str) -> InvalidValue:
    return InvalidValue(_("Unknown recording format '{format}'; use one of {formats}").format(
        format=fmt, formats=", ".join(FORMATS)))


class Recorder(can.Listener):
    """Writes every frame of a session to one file until stopped."""

    def __init__(self, session: Session, path: Path) -> None:
        self.session = session
        self.path = path
        self.format = path.suffix.lstrip(".")
        self.started = time.time()
        self.frames = 0
        self.skipped = 0
        """Frames the writer refused (e.g. a CAN FD frame in a classic-only format); the first reason in ``error``."""
        self.error: str | None = None
        self._queue: queue.SimpleQueue[can.Message | None] = queue.SimpleQueue()
        self._writer = open_writer(path)
        self._thread = threading.Thread(target=self._drain, name=f"recorder-{path.name}", daemon=True)
        self._thread.start()
        session.add_frame_listener(self)

    def on_message_received(self, msg: can.Message) -> None:
        self._queue.put(msg)

    def _drain(self) -> None:
        while True:
            msg = self._queue.get()
            if msg is None:
                break
            if msg.channel is not None:  # the frame may also sit in the monitor's trace: write a copy
                msg = copy.copy(msg)
                msg.channel = None
            try:
                self._writer.on_message_received(msg)
            except (ValueError, TypeError, OverflowError, struct.error) as exc:  # one bad frame never ends the file
                self.skipped += 1
                self.error = self.error or f"{type(exc).__name__}: {exc}"
                continue
            self.frames += 1
        self._writer.stop()

    def stop(self) -> None:
        self.session.remove_frame_listener(self)
        self._queue.put(None)
        self._thread.join(timeout=30)


@dataclass
class RecordingInfo:
    name: str
    format: str
    size: int
    modified: float
    active: bool
    frames: int | None

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "format": self.format, "size": self.size, "modified": self.modified,
                "active": self.active, "frames": self.frames}


class Recordings:
    """The recording files of one session, and the one recording that may be running."""

    def __init__(self, session: Session, directory: Path | None = None) -> None:
        self.session = session
        self._directory = directory
        self.active: Recorder | None = None
        self._lock = threading.Lock()

    @property
    def directory(self) -> Path:
        return self._directory or recordings_dir()

    def start(self, fmt: str) -> Recorder:
        if fmt not in FORMATS:
            raise unknown_format(fmt)
        with self._lock:
            if self.active is not None:
                raise Conflict(_("Already recording to {file}; stop it first").format(file=self.active.path.name))
            self.directory.mkdir(parents=True, exist_ok=True)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            path = self.directory / f"{self.session.id}-{stamp}.{fmt}"
            counter = 1
            while path.exists():
                counter += 1
                path = self.directory / f"{self.session.id}-{stamp}-{counter}.{fmt}"
            self.active = Recorder(self.session, path)
            return self.active

    def stop(self) -> Recorder:
        with self._lock:
            recorder = self.active
            if recorder is None:
                raise Conflict(_("No recording is running"))
            self.active = None
        recorder.stop()
        return recorder

    def close(self) -> None:
        """The session closes: the running recording stops (its file complete)."""
        with self._lock:
            recorder, self.active = self.active, None
        if recorder is not None:
            recorder.stop()

    def list(self) -> list[RecordingInfo]:
        if not self.directory.exists():
            return []
        active = self.active
        infos = []
        for path in self.directory.glob(f"{self.session.id}-*"):
            if not _SAFE_NAME.match(path.name):
                continue
            stat = path.stat()
            is_active = active is not None and active.path == path
            infos.append(RecordingInfo(path.name, path.suffix.lstrip("."), stat.st_size, stat.st_mtime, is_active,
                                       active.frames if is_active and active else None))
        return sorted(infos, key=lambda info: info.modified, reverse=True)

    def path(self, name: str) -> Path:
        path = self.directory / name
        if not _SAFE_NAME.match(name) or not name.startswith(f"{self.session.id}-") or not path.is_file():
            raise NotFound(_("No recording '{name}' in session '{session}'").format(name=name,
                                                                                    session=self.session.id))
        return path


class RecordingsPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def recordings(self) -> Recordings: ...


def recordings_for(session: Session) -> Recordings:
    """The session's recordings (made with the session's services when it opens, closed with them)."""
    services: RecordingsPart = session.opened_services()
    return services.recordings
