"""PDOs of a simulated node, driven by its own communication and mapping objects (CiA 301).

RPDO n: 0x1400+n-1 (COB-ID, transmission type) and 0x1600+n-1 (mapping); TPDO n: 0x1800+n-1 (COB-ID,
type, inhibit time in 100 µs, event timer in ms) and 0x1A00+n-1. A mapping entry is index<<16 | sub<<8 | bits.
Transmission types: 0 acyclic synchronous, 1..240 every n-th SYNC, 254/255 event-driven (on change, and
every event-timer period when it is set).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

from drivebench.device.profiles.pdo_notes import selecting_byte, static_mapping
from drivebench.errors import UnknownParameter
from drivebench.protocol.datatypes import decode, encode
from drivebench.simulator.host import DeviceHost
from drivebench.simulator.store import Abort

COB_INVALID = 0x80000000

# MICROMASTER (manual ch. 5.6, table 5-1): P2041 (0x27F9) keeps the PDO5/6 mappings as one bit per object and the
# transmission types as bytes / sync bits, so CANopen writes show up there (the traces read 0x2103 after mapping
# RPDO5 = 6040 + 6042, TPDO5 = 6041 + 6044). Only this direction is modelled: writing P2041 leaves the objects.
# It applies where the profile's pdo_rules keep the mappings as bits in that parameter (``mapping_bits``).
P2041 = 0x27F9
P2041_MAPPING: dict[int, tuple[str, int, int]] = {  # mapping index -> (direction, P2041 sub, bit shift)
    0x1604: ("rpdo", 2, 0), 0x1A04: ("tpdo", 2, 8), 0x1605: ("rpdo", 3, 0), 0x1A05: ("tpdo", 3, 8)}
P2041_TYPE: dict[int, tuple[int, int, int]] = {  # communication index -> (P2041 sub, bit shift, width)
    0x1800: (0, 0, 8), 0x1804: (0, 8, 8), 0x1805: (1, 0, 8), 0x1400: (1, 8, 1), 0x1404: (1, 9, 1), 0x1405: (1, 10, 1)}


@dataclass
class PdoConfig:
    number: int
    cob_id: int
    valid: bool
    trans_type: int
    inhibit_s: float
    event_s: float
    mapping: list[tuple[int, int, int]]
    sync_count: int = 0
    last_data: bytes | None = None
    last_sent: float = 0.0
    next_event: float = 0.0
    pending: bool = field(default=False)


def _int(value: object, default: int = 0) -> int:
    return value if isinstance(value, int) else default


def _mapping_bits_in(node: DeviceHost, index: int) -> bool:
    """The profile's pdo_rules say the parameter at ``index`` keeps PDO mappings as one bit per object."""
    rules = node.profile.pdo_rules
    refs = {selecting.ref for bits in (rules.mapping_bits if rules else []) for selecting in bits.pdos}
    for ref in refs:
        try:
            if node.store.catalog.resolve(ref).index == index:
                return True
        except UnknownParameter:
            continue
    return False


class PdoEngine:
    def __init__(self, node: DeviceHost) -> None:
        self.node = node
        self.rpdos: dict[int, PdoConfig] = {}
        self.tpdos: list[PdoConfig] = []
        self._lock = threading.Lock()
        node.store.add_write_check(self.check_write)
        if _mapping_bits_in(node, P2041) and node.store.has(P2041, 2):
            node.store.add_write_hook(self._mirror_p2041)

    # --- CiA 301 rules for changing a mapping (7.5.2.36/38): the device refuses what would break a PDO ----------
    def check_write(self, index: int, sub: int, raw: object) -> None:
        if not (0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF):
            return
        store = self.node.store
        comm_index = index - 0x200
        cob = _int(store.get(comm_index, 1)) if store.has(comm_index, 1) else COB_INVALID
        if not cob & COB_INVALID and self.node.profile.features.mapping_needs_invalid_pdo:
            # Mapping of an existing (valid) PDO: CiA 301 leaves the abort code to the device; the Lenze
            # manuals list 0x06040043 "General parameter incompatibility".
            raise Abort(0x06040043)
        if sub == 0:
            count = _int(raw)
            if count > _int(store.get(index, 0)) and count > self._max_entries(index):
                raise Abort(0x06090030)
            bits = 0
            for entry_sub in range(1, count + 1):
                if not store.has(index, entry_sub):
                    raise Abort(0x06090030)
                entry = _int(store.get(index, entry_sub))
                self._check_mappable(entry, receive=index < 0x1A00)
                bits += entry & 0xFF
            if bits > 64:
                raise Abort(0x06040042)
        elif _int(store.get(index, 0)) != 0:
            raise Abort(0x06040043)  # entries change only while sub 0 is 0 (mapping disabled)
        else:
            self._check_mappable(_int(raw), receive=index < 0x1A00)

    def _mirror_p2041(self, index: int, sub: int, raw: object) -> None:
        if index in P2041_MAPPING and sub == 0:
            direction, word, shift = P2041_MAPPING[index]
            entries = [(_int(self.node.store.get(index, n)) >> 16, (_int(self.node.store.get(index, n)) >> 8) & 0xFF)
                       for n in range(1, _int(raw) + 1) if self.node.store.has(index, n)]
            rules = self.node.profile.pdo_rules
            found = rules.bits_for(direction, (index & 0x1FF) + 1) if rules else None  # the profile's bit table
            bits = selecting_byte(found[0], entries) if found else None
            if bits is not None:
                self._set_p2041(word, shift, 8, bits)
        elif index in P2041_TYPE and sub == 2:
            word, shift, width = P2041_TYPE[index]
            trans_type = _int(raw)
            self._set_p2041(word, shift, width, trans_type if width == 8 else int(trans_type <= 240))  # 1 = sync

    def _set_p2041(self, word: int, shift: int, width: int, value: int) -> None:
        store = self.node.store
        if not store.has(P2041, word):
            return
        mask = ((1 << width) - 1) << shift
        store.set(P2041, word, (_int(store.get(P2041, word)) & ~mask) | (value << shift & mask), notify=False)

    def _max_entries(self, map_index: int) -> int:
        store = self.node.store
        return max((sub for (idx, sub) in store.snapshot() if idx == map_index), default=0)

    def _check_mappable(self, entry: int, *, receive: bool) -> None:
        if entry == 0:
            return
        index, sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        if 0x0001 <= index <= 0x0007 and sub == 0:
            return  # dummy entries (data type indices) fill gaps in an RPDO
        store = self.node.store
        if not store.has(index, sub):
            raise Abort(0x06020000)
        slot = store.slot(index, sub)
        if not slot.entry.pdo_mappable or (receive and not slot.entry.access.writable):
            raise Abort(0x06040041)
        size = slot.data_type.size
        if size is not None and bits != size * 8:
            raise Abort(0x06040043)

    def _read_config(self, comm_index: int, map_index: int, number: int) -> PdoConfig | None:
        store = self.node.store
        if not store.has(comm_index, 1):
            return None
        cob = _int(store.get(comm_index, 1))
        trans_type = _int(store.get(comm_index, 2), 255) if store.has(comm_index, 2) else 255
        inhibit = _int(store.get(comm_index, 3)) / 10000 if store.has(comm_index, 3) else 0.0
        event = _int(store.get(comm_index, 5)) / 1000 if store.has(comm_index, 5) else 0.0
        mapping: list[tuple[int, int, int]] = []
        count = _int(store.get(map_index, 0)) if store.has(map_index, 0) else 0
        for sub in range(1, count + 1):
            if not store.has(map_index, sub):
                break
            entry = _int(store.get(map_index, sub))
            mapping.append((entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF))
        if not count:
            mapping = self._static_mapping("rpdo" if map_index < 0x1A00 else "tpdo", number)
        return PdoConfig(number, cob & 0x7FF, not cob & COB_INVALID, trans_type, inhibit, event, mapping)

    def _static_mapping(self, direction: str, number: int) -> list[tuple[int, int, int]]:
        """Count 0 on an 8400 motec: the port's 4 process data words (see ``pdo_notes.static_mapping``)."""
        mapping = []
        for ref in static_mapping(self.node.profile, direction, number):
            try:
                item = self.node.store.catalog.resolve(ref)
            except UnknownParameter:
                return []
            mapping.append((item.index, item.subindex, (item.entry.data_type.size or 0) * 8))
        return mapping

    def reconfigure(self) -> None:
        rpdos: dict[int, PdoConfig] = {}
        tpdos: list[PdoConfig] = []
        for n in range(512):
            rx = self._read_config(0x1400 + n, 0x1600 + n, n + 1)
            if rx is not None and rx.valid:
                rpdos[rx.cob_id] = rx
            tx = self._read_config(0x1800 + n, 0x1A00 + n, n + 1)
            if tx is not None and tx.valid and tx.mapping:  # nothing mapped: nothing to send
                tpdos.append(tx)
        with self._lock:
            self.rpdos, self.tpdos = rpdos, tpdos

    def stop(self) -> None:
        with self._lock:
            self.tpdos = []

    # --- receive ----------------------------------------------------------------------------------------
    def on_frame(self, cob_id: int, data: bytes) -> None:
        config = self.rpdos.get(cob_id)
        if config is None:
            return
        bits_total = sum(bits for _, _, bits in config.mapping)
        if len(data) * 8 < bits_total:
            self.node.raise_emcy(0x8210, 0x10)  # PDO not processed due to length error
            return
        value = int.from_bytes(data, "little")
        offset = 0
        for index, sub, bits in config.mapping:
            field_value = (value >> offset) & ((1 << bits) - 1)
            offset += bits
            if index < 0x1000:  # dummy mapping
                continue
            try:
                slot = self.node.store.slot(index, sub)
                size = slot.data_type.size or (bits + 7) // 8
                raw = decode(slot.data_type, field_value.to_bytes(size, "little"))
                self.node.store.set(index, sub, raw)
            except Abort:
                continue

    # --- transmit ---------------------------------------------------------------------------------------
    def _pack(self, config: PdoConfig) -> bytes:
        value, offset = 0, 0
        for index, sub, bits in config.mapping:
            field_value = 0
            if index >= 0x1000:
                try:
                    slot = self.node.store.slot(index, sub)
                    field_value = int.from_bytes(encode(slot.data_type, slot.value), "little")
                except (Abort, ValueError):
                    field_value = 0
            value |= (field_value & ((1 << bits) - 1)) << offset
            offset += bits
        return value.to_bytes((offset + 7) // 8, "little")

    def _transmit(self, config: PdoConfig, now: float, data: bytes | None = None) -> None:
        data = self._pack(config) if data is None else data
        self.node.send(config.cob_id, data)
        config.last_data = data
        config.last_sent = now
        if config.event_s:
            config.next_event = now + config.event_s

    def on_operational(self) -> None:
        now = time.monotonic()
        with self._lock:
            for config in self.tpdos:
                if config.trans_type >= 254:
                    self._transmit(config, now)

    def on_sync(self) -> None:
        now = time.monotonic()
        with self._lock:
            for config in self.tpdos:
                if 1 <= config.trans_type <= 240:
                    config.sync_count += 1
                    if config.sync_count >= config.trans_type:
                        config.sync_count = 0
                        self._transmit(config, now)
                elif config.trans_type == 0:
                    data = self._pack(config)
                    if data != config.last_data:
                        self._transmit(config, now, data)

    def tick(self, now: float) -> float | None:
        """Send the event-driven TPDOs that are due or changed; returns when the next is due (an event timer, or a
        change held back by its inhibit time), None if only a change can make one due."""
        due: float | None = None
        with self._lock:
            for config in self.tpdos:
                if config.trans_type < 254:
                    continue
                data = self._pack(config)
                if now - config.last_sent < config.inhibit_s:
                    if data != config.last_data:
                        due = _earliest(due, config.last_sent + config.inhibit_s)
                elif (config.event_s and now >= config.next_event) or data != config.last_data:
                    self._transmit(config, now, data)
                if config.event_s:
                    due = _earliest(due, max(config.next_event, config.last_sent + config.inhibit_s))
        return due


def _earliest(first: float | None, second: float) -> float:
    return second if first is None else min(first, second)
