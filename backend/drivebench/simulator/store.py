"""A simulated drive's object dictionary: raw values for every entry its profile lists.

Reads and writes check what a real device checks and answer the CiA 301 abort codes:
unknown object 0x06020000, unknown subindex 0x06090011, write to read-only 0x06010002, read of write-only
0x06010001, wrong length 0x06070012/13 (0x06070010 where the profile's SDO server works in word and
double-word tasks), out of range 0x06090030/31/32.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from drivebench.device.formats.eds_export import eds_objects
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.factory_default import PREDEFINED_CONNECTION_SET
from drivebench.device.profiles.profile import Access, Entry, Profile
from drivebench.protocol.canopen.sdo_server import SdoAbort as Abort
from drivebench.protocol.datatypes import DataType, decode, encode

RawValue = int | float | str | bytes


@dataclass
class Slot:
    entry: Entry
    value: RawValue

    @property
    def data_type(self) -> DataType:
        return self.entry.data_type


WriteHook = Callable[[int, int, RawValue], None]
_NODEID_RE = re.compile(r"\$NODEID", re.IGNORECASE)

# CiA 301 communication objects whose default depends on the node id (when a profile gives no formula): the
# pre-defined connection set (the same table the parameter service's factory comparison reads).
_NODE_ID_DEFAULTS = {
    **PREDEFINED_CONNECTION_SET,
    (0x1201, 1): 0x80000640, (0x1201, 2): 0x800005C0,  # Lenze SDO2: 0x640/0x5C0 + id, invalid (bit 31) until enabled
}


def default_raw(entry: Entry, node_id: int, index: int = 0, sub: int = 0) -> RawValue:
    """The raw value a freshly powered device holds: the profile default, scaled, with $NODEID resolved."""
    value = entry.default
    if value is None:
        value = getattr(entry, "default_expr", None)  # CiA 306 formula such as $NODEID+0x300
    dt = entry.data_type
    if dt.is_string:
        if dt is DataType.VISIBLE_STRING or dt is DataType.UNICODE_STRING:
            return "" if value is None else str(value)
        if isinstance(value, str):
            try:
                return bytes.fromhex(value.replace(" ", ""))
            except ValueError:
                return value.encode("latin-1")
        return b""
    if isinstance(value, str):
        expr = _NODEID_RE.sub(str(node_id), value)
        try:
            value = eval(expr, {"__builtins__": {}}, {})
        except Exception:
            value = 0
    if value is None:
        offset = _NODE_ID_DEFAULTS.get((index, sub))
        if offset is not None:
            return offset + node_id
        value = entry.min if entry.min is not None and entry.min > 0 else 0
    if dt.is_float:
        return float(value) * float(entry.factor)
    raw = round(float(value) * float(entry.factor)) if entry.factor != 1 else int(value)
    limits = dt.raw_limits()
    if limits:
        raw = min(max(raw, limits[0]), limits[1])
    return raw


class ObjectStore:
    def __init__(self, profile: Profile, node_id: int, overrides: Mapping[str, object] | None = None) -> None:
        self.profile = profile
        self.node_id = node_id
        self.catalog = Catalog(profile)
        self._lock = threading.RLock()
        self._slots: dict[tuple[int, int], Slot] = {}
        self._indices: set[int] = set()
        self._hooks: list[WriteHook] = []
        self._checks: list[WriteHook] = []
        self._overrides = overrides or {}
        self.reset_all()
        self.saved: dict[tuple[int, int], RawValue] = self.snapshot()

    def reset_all(self) -> None:
        with self._lock:
            for item in self.catalog.items:
                key = (item.index, item.subindex)
                self._slots[key] = Slot(item.entry, default_raw(item.entry, self.node_id, *key))
                self._indices.add(item.index)
            # The rest of what the EDS lists: Lenze parameter sets 2..4 (their own values) and the sub 0 of coded
            # arrays ("highest sub-index supported", CiA 301 for an ARRAY; the EMF2178IB manual §10.3: "for all
            # array codes, the value of the highest subindex can be read out via subindex 0").
            for entry in eds_objects(self.profile):
                key = (entry.index, entry.subindex)
                if key not in self._slots:
                    self._slots[key] = Slot(entry, default_raw(entry, self.node_id, *key))
                    self._indices.add(entry.index)
            for ref, value in self._overrides.items():
                item = self.catalog.resolve(ref)
                slot = self._slots[(item.index, item.subindex)]
                slot.value = default_raw(item.entry.model_copy(update={"default": value}), self.node_id)

    def snapshot(self) -> dict[tuple[int, int], RawValue]:
        with self._lock:
            return {key: slot.value for key, slot in self._slots.items()}

    def restore(self, values: dict[tuple[int, int], RawValue], *, communication_only: bool = False) -> None:
        with self._lock:
            for key, value in values.items():
                if communication_only and not 0x1000 <= key[0] <= 0x1FFF:
                    continue
                if key in self._slots:
                    self._slots[key].value = value

    def add_write_check(self, check: WriteHook) -> None:
        """``check(index, sub, raw)`` before an SDO write is accepted; it raises Abort to refuse it."""
        self._checks.append(check)

    def add_write_hook(self, hook: WriteHook) -> None:
        """``hook(index, sub, raw)`` after every accepted write (SDO or RPDO)."""
        self._hooks.append(hook)

    def has(self, index: int, sub: int) -> bool:
        return (index, sub) in self._slots

    def slot(self, index: int, sub: int) -> Slot:
        slot = self._slots.get((index, sub))
        if slot is None:
            raise Abort(0x06090011 if index in self._indices else 0x06020000)
        return slot

    def get(self, index: int, sub: int) -> RawValue:
        with self._lock:
            return self.slot(index, sub).value

    def set(self, index: int, sub: int, value: RawValue, *, notify: bool = True) -> None:
        """Set a value from inside the device (behaviours, RPDOs): no access check."""
        with self._lock:
            self.slot(index, sub).value = value
        if notify:
            for hook in self._hooks:
                hook(index, sub, value)

    def get_ref(self, ref: str) -> RawValue:
        item = self.catalog.resolve(ref)
        return self.get(item.index, item.subindex)

    def set_ref(self, ref: str, value: RawValue) -> None:
        item = self.catalog.resolve(ref)
        self.set(item.index, item.subindex, value)

    # --- SDO server side --------------------------------------------------------------------------------
    def read(self, index: int, sub: int) -> bytes:
        with self._lock:
            slot = self.slot(index, sub)
            if slot.entry.access is Access.WO:
                raise Abort(0x06010001)
            try:
                return encode(slot.data_type, slot.value)
            except ValueError as exc:
                raise Abort(0x08000000) from exc

    def write(self, index: int, sub: int, data: bytes) -> None:
        with self._lock:
            slot = self.slot(index, sub)
            if not slot.entry.access.writable:
                raise Abort(0x06010002)
            data = self._sized(slot.data_type, data)
            raw = decode(slot.data_type, data)
            self._check_range(slot.entry, raw)
            self._check_gate(slot.entry)
            for check in self._checks:
                check(index, sub, raw)
            slot.value = raw
        for hook in self._hooks:
            hook(index, sub, raw)
        self._effects(slot.entry, raw)

    def _check_gate(self, entry: Entry) -> None:
        """The profile's ``writable_when``: the write is refused with its abort unless the other parameter holds
        one of the values (MICROMASTER motor data only while P0010 = 1)."""
        gate = entry.writable_when
        if gate is not None and self.get_ref(gate.ref) not in gate.values:
            raise Abort(gate.abort_code)

    def _effects(self, entry: Entry, raw: RawValue) -> None:
        """The profile's ``on_write``: what the device sets itself after the write (P3900 ends quick commissioning:
        P0010 back to 0)."""
        for effect in entry.on_write:
            if not effect.values or raw in effect.values:
                for ref, value in effect.sets.items():
                    item = self.catalog.resolve(ref)
                    self.set(item.index, item.subindex, default_raw(item.entry.model_copy(update={"default": value}),
                                                                    self.node_id))

    def _sized(self, data_type: DataType, data: bytes) -> bytes:
        """``data`` at the object's size, or the abort the device answers for a length that does not fit."""
        size = data_type.size
        if size is None or len(data) == size:
            return data
        if self.profile.features.sdo_word_tasks and len(data) <= 4 and size <= 4:
            if (len(data) == 4) != (size == 4):  # the manual's only length abort: "mixture between word and dword"
                raise Abort(0x06070010)
            if any(data[size:]):
                raise Abort(0x06090030)  # a word task whose value does not fit the byte object
            return data[:size].ljust(size, b"\0")
        raise Abort(0x06070012 if len(data) > size else 0x06070013)

    @staticmethod
    def _check_range(entry: Entry, raw: RawValue) -> None:
        if isinstance(raw, (str, bytes)):
            return
        value = raw / entry.factor if entry.factor != 1 else raw
        if entry.max is not None and value > entry.max + 1e-9:
            raise Abort(0x06090030)
        if entry.min is not None and value < entry.min - 1e-9:
            raise Abort(0x06090030)
        if entry.selection and isinstance(raw, int) and raw not in entry.selection:
            raise Abort(0x06090030)
