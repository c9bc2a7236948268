"""A simulated slave's object dictionary as the CoE SDO information service describes it (ETG.1000.6 5.6.3):
answered from the object store, so from the same profile the slave was built from.

Object code: an object with only subindex 0 is a VAR (unless the profile says ARRAY/RECORD), one with subindices an
ARRAY (a Lenze code with subcodes) or what the profile says. Access: readable entries are readable in every state;
writable ones in every state, except the objects the slave writes only in Pre-Operational (PDO mapping and
assignment). Entry descriptions carry the default, minimum and maximum of a number when asked (raw, as on the
bus); no unit type (the profiles keep no ETG unit index). A RECORD's data type is given as 0 (the standard names
a structure's own type index there; the profiles keep no such index).
"""

from __future__ import annotations

from collections.abc import Collection

from drivebench.device.profiles.profile import Entry, ObjectEntry, Parameter
from drivebench.protocol.canopen.sdo_server import SdoAbort
from drivebench.protocol.datatypes import encode
from drivebench.protocol.ethercat import coe_info
from drivebench.protocol.ethercat.coe_info import ListType, ObjectCode, ValueInfo
from drivebench.protocol.ethercat.coe_server import Abort
from drivebench.simulator.store import ObjectStore, default_raw

ABORT_NO_OBJECT, ABORT_NO_SUBINDEX = 0x06020000, 0x06090011


def _name(entry: Entry, *, of_object: bool) -> str:
    if isinstance(entry, ObjectEntry):
        return (entry.object_name or entry.name) if of_object else entry.name
    if isinstance(entry, Parameter):
        return entry.name if of_object or not entry.subcode_name else entry.subcode_name
    return entry.name


class StoreDictionary:
    def __init__(self, store: ObjectStore, pre_operational_only: Collection[int] = ()) -> None:
        self.store = store
        self.pre_operational_only = set(pre_operational_only)

    def _objects(self) -> dict[int, list[int]]:
        objects: dict[int, list[int]] = {}
        for index, sub in sorted(self.store.snapshot()):
            objects.setdefault(index, []).append(sub)
        return objects

    def _entry(self, index: int, sub: int) -> Entry:
        try:
            return self.store.slot(index, sub).entry
        except SdoAbort as exc:
            raise Abort(exc.code) from exc

    def _access(self, index: int, entry: Entry) -> int:
        bits = coe_info.READ_ALWAYS if entry.access.readable else 0
        if entry.access.writable:
            bits |= coe_info.WRITE_PREOP if index in self.pre_operational_only else coe_info.WRITE_ALWAYS
        if entry.pdo_mappable:
            bits |= coe_info.RXPDO_MAPPABLE if entry.access.writable else coe_info.TXPDO_MAPPABLE
        return bits

    def od_list(self, list_type: int) -> list[int]:
        objects = self._objects()
        if list_type == ListType.ALL:
            return list(objects)
        wanted = {ListType.RXPDO_MAPPABLE: coe_info.RXPDO_MAPPABLE, ListType.TXPDO_MAPPABLE: coe_info.TXPDO_MAPPABLE,
                  ListType.BACKUP: coe_info.WRITE_ALWAYS | coe_info.WRITE_PREOP,
                  ListType.SETTINGS: coe_info.WRITE_ALWAYS | coe_info.WRITE_PREOP}.get(ListType(list_type), 0)
        return [index for index, subs in objects.items()
                if any(self._access(index, self._entry(index, sub)) & wanted for sub in subs)]

    def object_description(self, index: int) -> coe_info.ObjectDescription:
        subs = self._objects().get(index)
        if not subs:
            raise Abort(ABORT_NO_OBJECT)
        entry = self._entry(index, subs[-1])
        if isinstance(entry, ObjectEntry) and entry.object_type != "VAR":
            code = ObjectCode[entry.object_type]
        else:
            code = ObjectCode.VAR if subs == [0] else ObjectCode.ARRAY
        data_type = 0 if code is ObjectCode.RECORD else entry.data_type.code
        return coe_info.ObjectDescription(index, data_type, subs[-1], code, _name(entry, of_object=True))

    def entry_description(self, index: int, subindex: int, value_info: int = 0) -> coe_info.EntryDescription:
        entry = self._entry(index, subindex)
        data_type = entry.data_type
        size = data_type.size
        if size is None:
            size = len(encode(data_type, self.store.get(index, subindex)))
        answered, values = 0, b""
        limits = data_type.raw_limits()
        if limits is not None:  # default, minimum and maximum of a number, raw as on the bus
            for flag, raw in ((ValueInfo.DEFAULT, default_raw(entry, self.store.node_id, index, subindex)),
                              (ValueInfo.MINIMUM, limits[0] if entry.min is None else round(entry.min * entry.factor)),
                              (ValueInfo.MAXIMUM, limits[1] if entry.max is None else round(entry.max * entry.factor))):
                if value_info & flag:
                    answered |= flag
                    values += encode(data_type, raw)
        return coe_info.EntryDescription(index, subindex, data_type.code, size * 8, self._access(index, entry),
                                         _name(entry, of_object=False), answered, values)
