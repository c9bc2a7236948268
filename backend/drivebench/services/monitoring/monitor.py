"""Live telegram monitor of one session: counters per COB-ID, service and node, bus load with history, a trace.

The listener thread (python-can notifier, and every thread that sends through the session's ObservedBus) only
counts: one lock, one dict entry per COB-ID (frames, bits), the current one-second load bucket, and a reference to
the frame in the trace ring. Service and node of a COB-ID, rates, shares and decoded trace text are worked out
when someone looks (``snapshot``, ``trace_rows``), from those raw figures.

Bounds: COB-ID table at most 2048 + the 29-bit ids seen; load history ``HISTORY_S`` one-second points; trace ring
``TRACE_CAPACITY`` frames; rate samples covering ``RATE_WINDOW_S``.

Filter and pause belong to a viewer (``MonitorView``): counters, load and the trace ring exist once per session and
always take every frame; a view chooses which rows it is shown, and a paused view repeats the snapshot taken at
pause and sees no telegram newer than the pause. Each websocket client has its own view; ``Monitor.defaults`` is
the view of the REST API and the one a new websocket client starts with.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Protocol

import can

from drivebench.device.profiles.number_base import shows_hex
from drivebench.i18n import N_, Text, gettext, shown
from drivebench.protocol.canopen.decode import (
    DecodedFrame,
    SdoContext,
    SdoTracker,
    Service,
    classify,
    decode_frame,
)
from drivebench.services.bus.sessions import Session
from drivebench.services.bus.views import vendor_emcy_text
from drivebench.services.monitoring.pdo_cob_ids import Owner, PdoCobIds
from drivebench.transport.busload import REORDER_S, FrameClock, LoadWindows, message_bits

TRACE_CAPACITY = 10_000
"""Frames kept in the trace ring (the newest)."""
HISTORY_S = 600
"""Seconds of bus-load history (one point per second)."""
RATE_WINDOW_S = 2
"""Rates are frames over the last this many closed one-second windows of frame time: a silent COB-ID is at 0/s
this long after its last frame."""
EXTENDED = 1 << 29
"""Key flag for 29-bit identifiers in the COB-ID table."""
FLOOD_BUS_PERCENT = 60.0
FLOOD_COB_PERCENT = 50.0
"""A COB-ID floods the bus when the load of the rate window is at least FLOOD_BUS_PERCENT and that COB-ID alone
takes FLOOD_COB_PERCENT of the bit rate."""
FLOOD_CACHE_S = 0.5

SERVICE_GROUPS = ("NMT", "SYNC", "EMCY", "TIME", "PDO", "SDO", "Heartbeat", "LSS", N_("Unknown"), N_("Error frame"))
"""What the service filter offers; PDO and SDO stand for all their kinds (the page shows them through _())."""
SERVICE_ORDER = [Service.NMT, Service.SYNC, Service.EMCY, Service.TIME,
                 Service.TPDO1, Service.TPDO2, Service.TPDO3, Service.TPDO4,
                 Service.TPDO_MORE, Service.RPDO1, Service.RPDO2, Service.RPDO3, Service.RPDO4, Service.RPDO_MORE,
                 Service.SDO_RX, Service.SDO_TX, Service.HEARTBEAT, Service.LSS, Service.UNKNOWN]
SERVICE_LABELS = {Service.SDO_RX: N_("SDO request (rx)"), Service.SDO_TX: N_("SDO response (tx)"),
                  Service.HEARTBEAT: N_("Heartbeat / boot-up"), Service.TPDO_MORE: N_("TPDO 5 and higher"),
                  Service.RPDO_MORE: N_("RPDO 5 and higher")}
"""Shown in each viewer's language (``view_snapshot``), as are "Unknown" and "Error frame"."""


def service_group(service: Service) -> str:
    if service.is_pdo:
        return "PDO"
    if service in (Service.SDO_RX, Service.SDO_TX):
        return "SDO"
    return service.value


@dataclass
class MonitorFilter:
    """What the views show (counting is never filtered). Empty sets mean all."""

    nodes: set[int] = field(default_factory=set)
    services: set[str] = field(default_factory=set)
    cob_min: int = 0
    cob_max: int = 0x1FFFFFFF

    def accepts(self, service: Service, node: int | None, cob_id: int) -> bool:
        if self.nodes and node not in self.nodes:
            return False
        if self.services and service_group(service) not in self.services:
            return False
        return self.cob_min <= cob_id <= self.cob_max

    def as_dict(self) -> dict[str, Any]:
        return {"nodes": sorted(self.nodes), "services": sorted(self.services),
                "cob_min": self.cob_min, "cob_max": self.cob_max}

    def key(self) -> tuple[Any, ...]:
        """Equal for equal filters (viewers with the same filter share one update)."""
        return tuple(sorted(self.nodes)), tuple(sorted(self.services)), self.cob_min, self.cob_max


@dataclass
class MonitorView:
    """One viewer's filter and pause; ``paused_at`` is the trace sequence number at pause (None: live)."""

    filter: MonitorFilter = field(default_factory=MonitorFilter)
    paused_at: int | None = None
    frozen: dict[str, Any] | None = None
    """The unfiltered snapshot taken at pause."""
    epoch: int = 0
    """The monitor's reset count at pause: after a reset, a paused view's trace is empty."""

    @property
    def paused(self) -> bool:
        return self.paused_at is not None


@dataclass
class _Sample:
    at: float
    frames: dict[int, int]
    errors: int


@lru_cache(maxsize=4096)
def _key_text(key: int) -> str:
    return f"0x{key & 0x1FFFFFFF:08X}" if key & EXTENDED else f"0x{key:03X}"


class Monitor(can.Listener):
    _cobs: dict[int, list[Any]]
    """key (COB-ID, EXTENDED flag for 29-bit) -> [frames, bits, monotonic time of the last frame]"""
    _last_error: float | None
    _samples: deque[_Sample]
    """Counts at the close of each of the last RATE_WINDOW_S + 1 load windows (the rates' ends)."""
    _load: LoadWindows
    _seq: int
    _frames: int
    _errors: int

    def __init__(self, session: Session, *, trace_capacity: int = TRACE_CAPACITY,
                 history_s: int = HISTORY_S) -> None:
        self._session = weakref.ref(session)
        self.session_id = session.id
        self.bitrate = session.spec.bitrate
        self.trace_capacity = trace_capacity
        self.history_s = history_s
        self.defaults = MonitorView()
        self.resets = 0
        self._lock = threading.Lock()
        self._wall_offset = time.time() - time.monotonic()
        self._trace: deque[tuple[int, can.Message, SdoContext | None]] = deque(maxlen=trace_capacity)
        self._clock = FrameClock()
        self._tracker = SdoTracker()
        self._pdo_cob_ids = PdoCobIds()
        """Outlives a reset: the devices keep their PDO configuration."""
        self._flood_cache: tuple[float, str | None] | None = None
        self._reset_locked(time.monotonic())

    @property
    def filter(self) -> MonitorFilter:
        """The default filter (REST API, new viewers)."""
        return self.defaults.filter

    @property
    def paused(self) -> bool:
        """Whether the default view (REST API, new viewers) is paused."""
        return self.defaults.paused

    # --- hot path (listener threads) ---------------------------------------------------------------------
    def on_message_received(self, msg: can.Message, _clock: Any = time.monotonic,
                            _bits: Any = message_bits) -> None:
        now = _clock()
        stamp = self._clock.time_of(msg.timestamp, now + self._wall_offset)
        if msg.is_error_frame:
            with self._lock:
                self._load.close_until(stamp - REORDER_S)
                self._errors += 1
                self._last_error = now
                self._seq += 1
                self._trace.append((self._seq, msg, None))
            return
        key = msg.arbitration_id | EXTENDED if msg.is_extended_id else msg.arbitration_id
        bits = _bits(msg)
        with self._lock:
            self._load.add(stamp, bits)  # first: a window it closes is sampled without it
            entry = self._cobs.get(key)
            if entry is None:
                entry = self._cobs[key] = [0, 0, now]
            entry[0] += 1
            entry[1] += bits
            entry[2] = now
            self._frames += 1
            self._seq = seq = self._seq + 1
            if 0x580 < key < 0x680:
                self._trace.append((seq, msg, self._tracker.observe(msg)))
                self._pdo_cob_ids.observe(key, msg.data)
                return
            self._trace.append((seq, msg, None))
            if 0x700 < key < 0x780 and msg.data == b"\0":
                self._pdo_cob_ids.boot(key - 0x700)

    def on_error(self, exc: Exception) -> None:
        """The notifier reports reader errors here; the session's own error catcher handles them."""

    # --- bookkeeping (under the lock) ------------------------------------------------------------------------
    def _reset_locked(self, now: float) -> None:
        self._cobs = {}
        self._frames = 0
        self._errors = 0
        self._last_error = None
        self._seq = 0
        self._trace.clear()
        self._tracker.reset()
        self._samples = deque(maxlen=RATE_WINDOW_S + 1)
        self._load = LoadWindows(self.bitrate, self.history_s, now + self._wall_offset, on_close=self._sample)
        self._started = now

    def _sample(self, end: float) -> None:
        """The counts as a load window closes (called by ``_load`` under the lock)."""
        self._samples.append(_Sample(end, {key: entry[0] for key, entry in self._cobs.items()}, self._errors))

    # --- control -----------------------------------------------------------------------------------------
    def totals(self) -> tuple[int, int]:
        """Frames and error frames counted since the last reset (a metrics scraper reads a reset as a restart)."""
        with self._lock:
            return self._frames, self._errors

    def reset(self) -> None:
        """Counters, history, peak and trace start again, for every viewer; a paused default view stays paused
        (at the empty state)."""
        with self._lock:
            self._reset_locked(time.monotonic())
            self.resets += 1
        if self.defaults.paused:
            self.defaults.paused_at = None
            self.pause()

    def follow_bitrate(self, bitrate: int) -> None:
        """The session's adapter runs at ``bitrate`` now (activate bit timing): the load is counted against it from
        here, and the counters start again (a share of the old rate would mean nothing at the new one)."""
        if bitrate != self.bitrate:
            self.bitrate = bitrate
            self.reset()

    def pause(self, view: MonitorView | None = None) -> None:
        view = view or self.defaults
        if view.paused:
            return
        view.frozen = self.live_snapshot()
        view.epoch = self.resets
        view.paused_at = self._seq

    def resume(self, view: MonitorView | None = None) -> None:
        view = view or self.defaults
        view.paused_at = None
        view.frozen = None

    def set_filter(self, new_filter: MonitorFilter, view: MonitorView | None = None) -> None:
        (view or self.defaults).filter = new_filter

    # --- views ---------------------------------------------------------------------------------------------
    def snapshot(self, view: MonitorView | None = None) -> dict[str, Any]:
        """Counters, rates, load and its peak, bus state, as ``view`` (default: the REST view) sees them: node and
        COB-ID rows that pass its filter; a paused view repeats the snapshot taken at pause."""
        view = view or self.defaults
        return self.view_snapshot(view.frozen or self.live_snapshot(), view)

    @staticmethod
    def view_snapshot(snapshot: dict[str, Any], view: MonitorView) -> dict[str, Any]:
        """``snapshot`` (from ``live_snapshot``) with the node and COB-ID rows ``view`` shows, its bus and flood
        sentences in the current language."""
        if snapshot.get("bus_text"):
            snapshot = {**snapshot, "bus_text": shown(snapshot["bus_text"])}
        if snapshot.get("flood"):
            snapshot = {**snapshot, "flood": {**snapshot["flood"], "text": shown(snapshot["flood"]["text"])}}
        rows = snapshot["services"]
        labels = [gettext(label) for label in (row["label"] for row in rows)]
        snapshot = {**snapshot, "services": [{**row, "label": label} for row, label in zip(rows, labels, strict=True)]}
        accepts = view.filter.accepts
        nodes = view.filter.nodes
        if view.filter.key() == _ALL:
            return {**snapshot, "paused": view.paused}
        return {**snapshot, "paused": view.paused, "filter": view.filter.as_dict(),
                "nodes": [row for row in snapshot["nodes"] if not nodes or row["node"] in nodes],
                "cob_ids": [row for row in snapshot["cob_ids"]
                            if accepts(_SERVICES[row["service"]], row["node"], _cob_in(row, view.filter.cob_min))]}

    def live_snapshot(self) -> dict[str, Any]:
        """The snapshot of now, unfiltered (every node and COB-ID row)."""
        now = time.monotonic()
        with self._lock:
            self._load.close_idle(now + self._wall_offset)
            cobs = {key: (entry[0], entry[1], entry[2]) for key, entry in self._cobs.items()}
            errors, last_error, frames = self._errors, self._last_error, self._frames
            last_second = self._load.last()
            peak, started = self._load.peak, self._started
            frame_rate = self._load.frames_per_s(RATE_WINDOW_S)
            current, reference = self._rate_window()
        elapsed = max(current.at - reference.at, 1e-3)
        total_bits = sum(entry[1] for entry in cobs.values())
        services: dict[Service, list[float]] = {service: [0, 0.0, 0] for service in SERVICE_ORDER}
        nodes: dict[int, list[float]] = {}
        cob_rows = []
        owners = self._channel_owners()
        classified = {key: owners.get(key) or _classify_key(key) for key in cobs}
        unanswered = _unanswered(classified, set(owners.values()), self._node_names())
        scan_cobs: list[int] = []
        """COB-IDs of the requests to ``unanswered``: one COB-ID row."""
        for key in sorted(cobs):
            count, bits, last_seen = cobs[key]
            rate = (current.frames.get(key, 0) - reference.frames.get(key, 0)) / elapsed
            service, node = classified[key]
            if node in unanswered:
                node = None
                scan_row = nodes.setdefault(SCAN_ROW, [0, 0.0, 0])
                scan_row[0] += count
                scan_row[1] += rate
                scan_row[2] += bits
                scan_cobs.append(key)
            service_row = services[service]
            service_row[0] += count
            service_row[1] += rate
            service_row[2] += bits
            if node is not None:
                node_row = nodes.setdefault(node, [0, 0.0, 0])
                node_row[0] += count
                node_row[1] += rate
                node_row[2] += bits
            elif scan_cobs and scan_cobs[-1] == key:
                continue  # one row for them all, below
            cob_rows.append({"cob_id": key & 0x1FFFFFFF, "extended": bool(key & EXTENDED),
                             "text": _key_text(key), "service": service.value, "node": node, "ids": 1,
                             "total": count, "rate": round(rate, 2),
                             "share_percent": round(100.0 * bits / total_bits, 2) if total_bits else 0.0,
                             "last_age_s": round(now - last_seen, 2)})
        if scan_cobs:
            cob_rows.append(_scan_cob_row(scan_cobs, nodes[SCAN_ROW], min(now - cobs[key][2] for key in scan_cobs),
                                          total_bits))
            cob_rows.sort(key=lambda row: (row["extended"], row["cob_id"]))
        names = self._node_names()
        load_now = self._load.percent(last_second[2]) if last_second else 0.0
        bus, bus_text = self._bus()
        flood = self._flood(cobs, current, reference, elapsed, names, owners)
        return {
            "session": self.session_id,
            "time": now + self._wall_offset,
            "since": started + self._wall_offset,
            "paused": False,
            "bitrate": self.bitrate,
            "bus": bus,
            "bus_text": bus_text,
            "flood": flood,
            "totals": {"frames": frames, "bits": total_bits, "rate": round(frame_rate, 2), "errors": errors,
                       "error_rate": round((current.errors - reference.errors) / elapsed, 2),
                       "last_error_age_s": round(now - last_error, 2) if last_error is not None else None},
            "load": {"percent": round(load_now, 2), "second": last_second[0] if last_second else None,
                     "peak_percent": round(peak[0], 2),
                     "peak_time": peak[1] if peak[0] else None,
                     "average_percent": round(100.0 * total_bits / self.bitrate / max(now - started, 1e-3), 2)},
            "services": [{"service": service.value, "label": SERVICE_LABELS.get(service, service.value),
                          "group": service_group(service), "total": int(row[0]), "rate": round(row[1], 2)}
                         for service, row in services.items()],
            "nodes": [{"node": None if node == SCAN_ROW else node, "name": names.get(node), "total": int(row[0]),
                       "rate": round(row[1], 2),
                       "share_percent": round(100.0 * row[2] / total_bits, 2) if total_bits else 0.0,
                       **({"unanswered_ids": len(unanswered)} if node == SCAN_ROW else {})}
                      for node, row in sorted(nodes.items())],
            "cob_ids": cob_rows,
            "filter": MonitorFilter().as_dict(),
        }

    def _bus(self) -> tuple[dict[str, Any], Text | None]:
        """The session's bus state (controller and adapter link, see :class:`BusHealth`) and its sentence (worded
        when shown: ``view_snapshot``)."""
        session = self._session()
        if session is None:
            return {"state": "active", "adapter_state": "active", "tx_errors": None, "rx_errors": None,
                    "reported_age_s": None}, None
        health = session.health
        data = health.as_dict()
        return {key: data[key] for key in ("state", "adapter_state", "tx_errors", "rx_errors",
                                           "reported_age_s")}, data["text"]

    def _flood(self, cobs: dict[int, tuple[int, int, float]], current: _Sample, reference: _Sample, elapsed: float,
               names: dict[int, str], owners: Mapping[int, Owner]) -> dict[str, Any] | None:
        """The COB-ID that holds the bus (a babbling node), from the bits of the rate window; None if none does."""
        capacity = self.bitrate * elapsed
        recent = {key: (current.frames.get(key, 0) - reference.frames.get(key, 0)) * bits / count
                  for key, (count, bits, _) in cobs.items() if count}
        if not recent or sum(recent.values()) < FLOOD_BUS_PERCENT / 100 * capacity:
            return None
        key = max(recent, key=recent.__getitem__)
        share = 100.0 * recent[key] / capacity
        if share < FLOOD_COB_PERCENT:
            return None
        service, node = owners.get(key) or _classify_key(key)
        cob = f"COB-ID {_key_text(key)}"
        who = cob if not node else Text(N_("{cob} ({service} of node {node}, {name})") if node in names else
                                         N_("{cob} ({service} of node {node})"), cob=cob, service=service.value,
                                         node=node, name=names.get(node, ""))
        return {"cob_id": _key_text(key), "node": node, "load_percent": round(share, 1),
                "text": Text(N_("{who} floods the bus: {share} % bus load over the last {seconds} s (a babbling "
                                 "node?). On a real bus every frame with a higher COB-ID loses arbitration: those "
                                 "nodes cannot answer until it stops."), who=who, share=f"{share:.0f}",
                              seconds=f"{elapsed:.0f}")}

    def flood_text(self) -> str | None:
        """The babbling-node sentence for the Plant page in the reader's language (at most one snapshot per
        FLOOD_CACHE_S)."""
        now = time.monotonic()
        cached = self._flood_cache
        if cached is None or now - cached[0] >= FLOOD_CACHE_S:
            flood = self.live_snapshot()["flood"]
            cached = self._flood_cache = (now, flood["text"] if flood else None)
        return shown(cached[1]) if cached[1] is not None else None

    def _rate_window(self) -> tuple[_Sample, _Sample]:
        """The counts at the close of the newest load window and RATE_WINDOW_S windows before (or at the reset, while
        fewer have closed); both the same while none has."""
        samples = self._samples
        start = _Sample(self._started + self._wall_offset, {}, 0)
        if not samples:
            return start, start
        return samples[-1], samples[0] if len(samples) > RATE_WINDOW_S else start

    def history(self, since_second: float | None = None) -> list[tuple[float, float]]:
        """(wall time of the second, load %) for the closed one-second windows after ``since_second``."""
        with self._lock:
            self._load.close_idle(time.monotonic() + self._wall_offset)
            points = list(self._load.history)
        return [(float(second), round(100.0 * bits / self.bitrate, 3)) for second, _, bits in points
                if since_second is None or second > since_second]

    @property
    def last_seq(self) -> int:
        return self._seq

    def trace_rows(self, *, after: int = 0, limit: int = 200,
                   view: MonitorView | None = None) -> list[dict[str, Any]]:
        """The newest ``limit`` telegrams after sequence number ``after`` that pass the filter, oldest first."""
        return self.trace_since(after, limit, view=view)[0]

    def trace_since(self, after: int, limit: int, until: int | None = None,
                    view: MonitorView | None = None) -> tuple[list[dict[str, Any]], int]:
        """Like ``trace_rows``, plus the sequence number the rows reach (pass it as ``after`` next time); with
        ``until``, only telegrams up to that sequence number. ``view`` (default: the REST view) filters; a paused
        view sees nothing newer than its pause.

        Only rows that pass the filter are decoded; the filter is checked on the COB-ID first (NMT: its target).
        """
        view = view or self.defaults
        if view.paused_at is not None:
            stop = view.paused_at if view.epoch == self.resets else 0
            until = stop if until is None else min(until, stop)
        with self._lock:
            entries = list(self._trace) if after == 0 else self._entries_after(after)
        newest = entries[-1][0] if entries else after
        if until is not None:
            newest = min(newest, max(until, after))
        accepts = view.filter.accepts
        lookups = _Lookups(self._session())
        owners = self._channel_owners()
        rows: list[dict[str, Any]] = []
        for seq, msg, context in reversed(entries):
            if seq > newest:
                continue
            if seq <= after:
                break
            if msg.is_error_frame:
                service, node = Service.ERROR_FRAME, None
            else:
                service, node = owners.get(msg.arbitration_id) or classify(msg.arbitration_id, msg.is_extended_id)
                if service is Service.NMT and len(msg.data) >= 2 and msg.data[1]:
                    node = msg.data[1]
            if not accepts(service, node, msg.arbitration_id):
                continue
            decoded = decode_frame(msg, names=lookups.name, abort_texts=lookups.abort_texts, emcy_texts=lookups.emcy,
                                   sdo_context=context, owner=owners.get(msg.arbitration_id),
                                   hex_words=lookups.reads_hex)
            rows.append(_row(seq, decoded))
            if len(rows) >= limit:
                break
        rows.reverse()
        return rows, newest

    def _entries_after(self, after: int) -> list[tuple[int, can.Message, SdoContext | None]]:
        trace = self._trace
        if not trace or trace[-1][0] <= after:
            return []
        newer = trace[-1][0] - after
        if newer >= len(trace):
            return list(trace)
        return [trace[i] for i in range(len(trace) - newer, len(trace))]

    def counts_for(self, cob_ids: Iterable[int]) -> int:
        with self._lock:
            return sum(self._cobs[c][0] for c in cob_ids if c in self._cobs)

    def _channel_owners(self) -> dict[int, Owner]:
        """Where the node and service of a COB-ID are not those of the predefined connection set (``classify``):
        COB-ID -> (service, node). The session nodes' additional SDO channels (their profiles' ``sdo_channels``):
        0x5C5 is node 5's SDO2 answer, not node 69's default SDO; and the PDOs whose COB-IDs the bus has shown
        (:mod:`~drivebench.services.monitoring.pdo_cob_ids`): 0x2A3 is node 3's TPDO1 once it was moved there,
        and 0x183 no longer node 3's."""
        session = self._session()
        sdo: dict[int, tuple[Service, int]] = {}
        nodes = dict(session.nodes) if session is not None else {}
        for node_id, node in nodes.items():
            for channel in node.profile.sdo_channels if node.profile else []:
                if node_id <= channel.max_node_id:
                    request, answer = channel.cob_ids(node_id)
                    sdo[request], sdo[answer] = (Service.SDO_RX, node_id), (Service.SDO_TX, node_id)
        with self._lock:
            seen, booted = self._pdo_cob_ids.copy()
        owners: dict[int, Owner] = dict(PdoCobIds.owners(seen, booted, sdo, nodes)) if seen else {}
        owners.update(sdo)
        return owners

    def _node_names(self) -> dict[int, str]:
        session = self._session()
        if session is None:
            return {}
        return {node_id: node.device_name for node_id, node in list(session.nodes.items())}

    def buffer_sizes(self) -> dict[str, int]:
        """Current fill of each bounded buffer (for the memory benchmark)."""
        with self._lock:
            return {"trace": len(self._trace), "history": len(self._load.history), "cob_ids": len(self._cobs),
                    "rate_samples": len(self._samples)}


_SERVICES = {service.value: service for service in Service}
_ALL = MonitorFilter().key()


SCAN_ROW = 1000
"""The node table's key for SDO requests to node ids that are not in the session and sent nothing themselves (a
scan asking all 127): one row, ``node`` None, with ``unanswered_ids``."""
_SENT_BY_THE_NODE = {Service.SDO_TX, Service.HEARTBEAT, Service.EMCY, Service.TPDO1, Service.TPDO2, Service.TPDO3,
                     Service.TPDO4, Service.TPDO_MORE}


def _scan_cob_row(keys: list[int], counts: list[float], age: float, total_bits: int) -> dict[str, Any]:
    """The COB-ID table's one row for the SDO requests to node ids that never answered (``ids`` of them, from
    ``cob_id`` to ``cob_last``): a scan's 0x601-0x67F, without the nodes that answered."""
    first, last = keys[0], keys[-1]
    return {"cob_id": first, "cob_last": last, "extended": False,
            "text": _key_text(first) if first == last else f"{_key_text(first)}–{_key_text(last)}",
            "service": Service.SDO_RX.value, "node": None, "ids": len(keys), "total": int(counts[0]),
            "rate": round(counts[1], 2), "share_percent": round(100.0 * counts[2] / total_bits, 2) if total_bits
            else 0.0, "last_age_s": round(age, 2)}


def _unanswered(classified: Mapping[int, tuple[Service, int | None]], owned: set[Owner],
                names: Mapping[int, str]) -> set[int]:
    """Node ids only asked (SDO requests), never heard from, and not in the session."""
    asked = {node for service, node in classified.values() if service is Service.SDO_RX and node is not None}
    heard = {node for service, node in classified.values() if service in _SENT_BY_THE_NODE}
    return {node for node in asked - heard if node not in names and (Service.SDO_RX, node) not in owned}


@lru_cache(maxsize=4096)
def _classify_key(key: int) -> tuple[Service, int | None]:
    return classify(key & 0x1FFFFFFF, bool(key & EXTENDED))


def _cob_in(row: Mapping[str, Any], cob_min: int) -> int:
    """The row's COB-ID for the filter: of a row for several (the scan's requests), the first at or above
    ``cob_min``."""
    return min(max(row["cob_id"], cob_min), row.get("cob_last", row["cob_id"]))


def _row(seq: int, decoded: DecodedFrame) -> dict[str, Any]:
    return {"seq": seq, "time": decoded.timestamp, "cob_id": decoded.cob_id_text, "service": decoded.service.value,
            "group": service_group(decoded.service), "node": decoded.node, "dlc": decoded.dlc,
            "hex": decoded.data_hex, "summary": decoded.summary, "text": decoded.text}


class _Lookups:
    """The profile's words for a session's nodes: object names, abort texts, EMCY texts."""

    def __init__(self, session: Session | None) -> None:
        self.session = session

    def name(self, node_id: int, index: int, subindex: int) -> str | None:
        node = self.session.nodes.get(node_id) if self.session else None
        catalog = node.catalog if node else None
        item = catalog.by_address(index, subindex) if catalog else None
        return f"{item.ref} {item.name}" if item else None

    def reads_hex(self, node_id: int, index: int, subindex: int) -> bool:
        """The object's value reads in hex by the Parameters tab's rule (:func:`number_base.shows_hex`)."""
        node = self.session.nodes.get(node_id) if self.session else None
        catalog = node.catalog if node else None
        item = catalog.by_address(index, subindex) if catalog else None
        return item is not None and shows_hex(item)

    def abort_texts(self, node_id: int) -> Mapping[int, str] | None:
        node = self.session.nodes.get(node_id) if self.session else None
        return node.profile.abort_texts.texts if node and node.profile and node.profile.abort_texts else None

    def emcy(self, node_id: int, code: int, data: bytes) -> str | None:
        node = self.session.nodes.get(node_id) if self.session else None
        return vendor_emcy_text(node, code, data) if node is not None else None


def attach(session: Session) -> Monitor:
    """A monitor on the session's frames (made with the session's services when it opens)."""
    monitor = Monitor(session)
    session.add_frame_listener(monitor)
    session.health.notes.append(monitor.flood_text)
    return monitor


class MonitorPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def monitor(self) -> Monitor: ...


def monitor_for(session: Session) -> Monitor:
    services: MonitorPart = session.opened_services()
    return services.monitor
