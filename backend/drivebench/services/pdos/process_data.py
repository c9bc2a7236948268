"""Live process data of a session: decode PDO frames by the mappings read from the devices, send RPDOs once
or cyclically, and produce SYNC.

Frames arrive in the bus threads (``Session.add_frame_listener``); each decoded PDO is handed to the watchers
(websockets) as the latest sample per COB-ID, so a fast PDO never floods a slow browser. Cyclic RPDOs belong to
an owner (one websocket): when it goes away, ``stop_owner`` ends them.
"""

from __future__ import annotations

import asyncio
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import can
from pydantic import BaseModel

from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.number_base import hex_digits, shows_hex
from drivebench.device.profiles.profile import Entry
from drivebench.device.profiles.scaling import from_raw, to_raw
from drivebench.errors import Conflict, DriveBenchError, InvalidValue, NotFound
from drivebench.i18n import N_, _
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.datatypes import decode, encode
from drivebench.services.bus.sessions import Session
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import Direction, PdoConfig

SYNC_COB_ID = 0x080
MIN_CYCLE_MS = 1


class Signal(BaseModel):
    ref: str
    name: str
    raw: int | float | str | None
    value: int | float | str | None
    unit: str | None = None
    text: str | None = None
    """Selection-list meaning or the names of the set bits."""
    hex: str | None = None
    """The value as it reads, in hex, where it is a word rather than an amount (a status word ``0x0237``, a
    COB-ID: :func:`drivebench.device.profiles.number_base.shows_hex`)."""
    bit_offset: int
    bits: int


class Sample(BaseModel):
    node_id: int
    direction: Direction
    number: int
    cob_id: int
    data: str
    """Frame bytes in hex, as on the wire."""
    t: float
    """Frame time (seconds since the epoch)."""
    signals: list[Signal]


@dataclass
class Layout:
    node_id: int
    config: PdoConfig
    entries: list[tuple[str, str, Entry | None, int]]
    """(ref, name, profile entry, bits) in mapping order; entry None for dummy/unknown entries."""
    hex_refs: frozenset[str] = frozenset()
    """The refs whose values read in hex (status and control words, COB-IDs)."""


def _layout(catalog: Catalog, node_id: int, config: PdoConfig) -> Layout:
    entries = []
    hex_refs = set()
    for mapped in config.entries:
        item = catalog.by_address(mapped.index, mapped.subindex)
        entries.append((mapped.ref, mapped.name, item.entry if item else None, mapped.bits))
        if item is not None and shows_hex(item):
            hex_refs.add(mapped.ref)
    return Layout(node_id, config, entries, frozenset(hex_refs))


def unpack(layout: Layout, data: bytes, t: float) -> Sample:
    value = int.from_bytes(data, "little")
    offset, signals = 0, []
    for ref, name, entry, bits in layout.entries:
        field_bits = (value >> offset) & ((1 << bits) - 1)
        raw: int | float | str | None = None
        scaled: int | float | str | None = None
        unit = text = shown_hex = None
        if entry is not None and offset + bits <= len(data) * 8:
            size = entry.data_type.size or (bits + 7) // 8
            decoded = decode(entry.data_type, field_bits.to_bytes(size, "little"))
            if not isinstance(decoded, bytes):
                shown = from_raw(entry, decoded)
                raw, unit, text = decoded, shown.unit, shown.text
                scaled = shown.value if not isinstance(shown.value, bytes) else None
                if ref in layout.hex_refs and isinstance(decoded, int):
                    shown_hex = hex_digits(decoded, size)
        signals.append(Signal(ref=ref, name=name, raw=raw, value=scaled, unit=unit, text=text, hex=shown_hex,
                              bit_offset=offset, bits=bits))
        offset += bits
    config = layout.config
    return Sample(node_id=layout.node_id, direction=config.direction, number=config.number, cob_id=config.cob_id,
                  data=data.hex(" ").upper(), t=t, signals=signals)


def pack(layout: Layout, values: dict[str, str]) -> bytes:
    """Engineering values by ref -> frame bytes (validated against the profile; missing values send 0)."""
    unknown = set(values) - {ref for ref, _, _, _ in layout.entries}
    if unknown:
        config = layout.config
        raise InvalidValue(_("{refs} is not mapped into {pdo}; read the PDOs again.").format(
            refs=", ".join(sorted(unknown)), pdo=f"{config.direction.upper()}{config.number}"))
    value, offset = 0, 0
    for ref, _name, entry, bits in layout.entries:
        text = values.get(ref, "").strip()
        field_bits = 0
        if entry is not None and text:
            raw = to_raw(entry, text, ref=ref)
            field_bits = int.from_bytes(encode(entry.data_type, raw), "little")
        value |= (field_bits & ((1 << bits) - 1)) << offset
        offset += bits
    return value.to_bytes((offset + 7) // 8, "little")


@dataclass
class Watcher:
    """One websocket's view: the newest sample per COB-ID since it last looked."""

    owner: str
    loop: asyncio.AbstractEventLoop
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    latest: dict[int, Sample] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def push(self, sample: Sample) -> None:
        with self.lock:
            self.latest[sample.cob_id] = sample
        self.loop.call_soon_threadsafe(self.wake.set)

    def take(self) -> list[Sample]:
        with self.lock:
            samples, self.latest = list(self.latest.values()), {}
        self.wake.clear()
        return samples


class _FrameTap(can.Listener):
    def __init__(self, on_frame: Callable[[can.Message], None]) -> None:
        self.on_frame = on_frame

    def on_message_received(self, msg: can.Message) -> None:
        if not msg.is_error_frame and not msg.is_remote_frame and not msg.is_extended_id:
            self.on_frame(msg)


class ProcessData:
    """Process data of one session (made with the session's services when it opens)."""

    def __init__(self, session: Session) -> None:
        self._session = weakref.ref(session)
        self.layouts: dict[int, Layout] = {}
        self.watchers: dict[str, Watcher] = {}
        self.cyclic: dict[tuple[str, int], asyncio.Task[None]] = {}
        self.sync_period_ms: int | None = None
        self._sync_stop: threading.Event | None = None
        self._lock = threading.Lock()
        self._tap = _FrameTap(self._on_frame)
        self._tapped = False

    @property
    def session(self) -> Session:
        session = self._session()
        if session is None:
            raise NotFound(_("The session is closed."))
        return session

    # --- layouts -----------------------------------------------------------------------------------------
    async def load(self, node_id: int) -> list[PdoConfig]:
        """Read the node's PDOs and decode its valid PDOs from now on."""
        session = self.session
        configs = await pdo.read_pdos(session, node_id)
        catalog = session.node(node_id).catalog
        assert catalog is not None  # read_pdos raised NotFound otherwise
        with self._lock:
            self.layouts = {cob: lay for cob, lay in self.layouts.items() if lay.node_id != node_id}
            for config in configs:
                if config.valid and config.entries:
                    self.layouts[config.cob_id] = _layout(catalog, node_id, config)
        return configs

    def layout(self, node_id: int, direction: Direction, number: int) -> Layout:
        for lay in self.layouts.values():
            config = lay.config
            if (lay.node_id, config.direction, config.number) == (node_id, direction, number):
                return lay
        raise NotFound(_("{pdo} of node {node} is not valid and mapped (or its mapping was not read yet).").format(
            pdo=f"{direction.upper()}{number}", node=node_id))

    def _on_frame(self, msg: can.Message) -> None:
        lay = self.layouts.get(msg.arbitration_id)
        if lay is None:
            return
        sample = unpack(lay, bytes(msg.data), msg.timestamp or time.time())
        for watcher in list(self.watchers.values()):
            watcher.push(sample)

    # --- watchers ----------------------------------------------------------------------------------------
    def watch(self, owner: str) -> Watcher:
        watcher = Watcher(owner, asyncio.get_running_loop())
        self.watchers[owner] = watcher
        if not self._tapped:
            self.session.add_frame_listener(self._tap)
            self._tapped = True
        return watcher

    def unwatch(self, owner: str) -> None:
        self.watchers.pop(owner, None)
        self.stop_owner(owner)
        if not self.watchers and self._tapped:
            session = self._session()
            if session is not None:
                session.remove_frame_listener(self._tap)
            self._tapped = False

    # --- sending -----------------------------------------------------------------------------------------
    async def send_rpdo(self, node_id: int, number: int, values: dict[str, str]) -> bytes:
        lay = self.layout(node_id, "rpdo", number)
        data = pack(lay, values)
        await asyncio.to_thread(frames_of(self.session.network).send, lay.config.cob_id, data)
        return data

    async def start_cyclic(self, owner: str, node_id: int, number: int, values: dict[str, str],
                           period_ms: int) -> bytes:
        if owner not in self.watchers:
            raise Conflict(_("Cyclic sending needs the live view open (it stops when the browser disconnects)."),
                           hint=N_("Reload the PDO tab and try again."))
        if period_ms < MIN_CYCLE_MS:
            raise InvalidValue(_("The cycle time must be at least {time} ms.").format(time=MIN_CYCLE_MS))
        lay = self.layout(node_id, "rpdo", number)
        data = pack(lay, values)
        cob_id = lay.config.cob_id
        self.stop_cyclic(owner, cob_id)
        network = self.session.network

        async def run() -> None:
            while True:
                await asyncio.to_thread(frames_of(network).send, cob_id, data)
                await asyncio.sleep(period_ms / 1000)

        self.cyclic[(owner, cob_id)] = asyncio.get_running_loop().create_task(run())
        return data

    def stop_cyclic(self, owner: str, cob_id: int) -> bool:
        task = self.cyclic.pop((owner, cob_id), None)
        if task is not None:
            task.cancel()
        return task is not None

    def stop_node(self, node_id: int) -> int:
        """End every cyclic RPDO to the node (the safety guard's trip); how many were running."""
        mine = {cob for cob, lay in self.layouts.items() if lay.node_id == node_id}
        keys = [key for key in self.cyclic if key[1] in mine]
        for key in keys:
            self.cyclic.pop(key).cancel()
        return len(keys)

    def stop_owner(self, owner: str) -> None:
        for key in [k for k in self.cyclic if k[0] == owner]:
            self.cyclic.pop(key).cancel()

    def cyclic_cob_ids(self) -> set[int]:
        return {cob for _, cob in self.cyclic}

    # --- SYNC producer -----------------------------------------------------------------------------------
    def start_sync(self, period_ms: int) -> None:
        if not 1 <= period_ms <= 65535:
            raise InvalidValue(_("The SYNC period must be 1 ... 65535 ms."))
        self.stop_sync()
        stop = threading.Event()
        network = self.session.network

        def run() -> None:
            next_at = time.monotonic()
            while not stop.is_set():
                try:
                    frames_of(network).send(SYNC_COB_ID, b"")
                except DriveBenchError:
                    return  # the bus went away (session closed)
                next_at += period_ms / 1000
                stop.wait(max(0.0, next_at - time.monotonic()))

        self._sync_stop, self.sync_period_ms = stop, period_ms
        threading.Thread(target=run, name="sync-producer", daemon=True).start()

    def stop_sync(self) -> None:
        if self._sync_stop is not None:
            self._sync_stop.set()
        self._sync_stop, self.sync_period_ms = None, None

    def close(self) -> None:
        """The session closes: SYNC and the cyclic RPDOs stop."""
        self.stop_sync()
        for task in self.cyclic.values():
            task.cancel()
        self.cyclic.clear()


class ProcessDataPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def process_data(self) -> ProcessData: ...


def service(session: Session) -> ProcessData:
    services: ProcessDataPart = session.opened_services()
    return services.process_data
