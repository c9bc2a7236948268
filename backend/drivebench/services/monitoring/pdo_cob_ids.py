"""Which node's PDO a COB-ID is, from the PDO communication parameters the bus has shown (CiA 301 0x1400-0x15FF
RPDOs, 0x1800-0x19FF TPDOs, sub-index 1: COB-ID, bit 31 = not valid).

Whatever reads or writes sub-index 1 of those objects over SDO on this bus - the PDO editor reading or applying, a
parameter read or write, a set download, another tool - passes the monitor, and the value its server confirmed is
kept here: a frame on a PDO's COB-ID is that PDO of its node, and a PDO moved away from its default COB-ID (the
profile's ``$NODEID`` formula, else CiA 301's predefined set) or made invalid no longer claims the default. A node's
boot-up forgets what was seen of it: it has loaded its communication parameters anew.

EtherCAT has no COB-IDs (its PDOs travel in the cyclic frame): nothing to attribute there.
"""

from __future__ import annotations

from collections.abc import Mapping

from drivebench.device.formats.eds import resolve_node_expr
from drivebench.device.profiles.profile import ObjectEntry
from drivebench.protocol.canopen.decode import Service
from drivebench.protocol.canopen.sdo_confirmed import ConfirmedValues
from drivebench.services.bus.sessions import SessionNode

COB_INVALID = 1 << 31
RPDO_BASE, TPDO_BASE, PDO_OBJECTS = 0x1400, 0x1800, 0x200
_NUMBERED = {(TPDO_BASE, 1): Service.TPDO1, (TPDO_BASE, 2): Service.TPDO2, (TPDO_BASE, 3): Service.TPDO3,
             (TPDO_BASE, 4): Service.TPDO4, (RPDO_BASE, 1): Service.RPDO1, (RPDO_BASE, 2): Service.RPDO2,
             (RPDO_BASE, 3): Service.RPDO3, (RPDO_BASE, 4): Service.RPDO4}
_PREDEFINED = {(TPDO_BASE, 1): 0x180, (TPDO_BASE, 2): 0x280, (TPDO_BASE, 3): 0x380, (TPDO_BASE, 4): 0x480,
               (RPDO_BASE, 1): 0x200, (RPDO_BASE, 2): 0x300, (RPDO_BASE, 3): 0x400, (RPDO_BASE, 4): 0x500}

Owner = tuple[Service, int | None]
"""(service, node) of a COB-ID; node None: nobody's that the session knows of."""


def is_pdo_cob_id(index: int, subindex: int) -> bool:
    return subindex == 1 and (RPDO_BASE <= index < RPDO_BASE + PDO_OBJECTS or
                              TPDO_BASE <= index < TPDO_BASE + PDO_OBJECTS)


def _kind(index: int) -> tuple[int, int]:
    """(communication base, PDO number) of a communication parameter object."""
    base = TPDO_BASE if index >= TPDO_BASE else RPDO_BASE
    return base, index - base + 1


def pdo_service(index: int) -> Service:
    base, number = _kind(index)
    return _NUMBERED.get((base, number)) or (Service.TPDO_MORE if base == TPDO_BASE else Service.RPDO_MORE)


def default_cob_id(node: SessionNode | None, node_id: int, index: int) -> int | None:
    """The COB-ID the PDO has before anyone changes it: the profile's formula, else CiA 301's predefined set."""
    catalog = node.catalog if node is not None else None
    item = catalog.by_address(index, 1) if catalog is not None else None
    formula = item.entry.default_expr if item is not None and isinstance(item.entry, ObjectEntry) else None
    if formula:
        try:
            return resolve_node_expr(formula, node_id) & 0x7FF
        except ValueError:
            pass
    base = _PREDEFINED.get(_kind(index))
    return base + node_id if base is not None else None


class PdoCobIds:
    """What the bus showed of PDO COB-IDs. ``observe`` and ``boot`` run on the monitor's hot path (under its lock)."""

    def __init__(self) -> None:
        self._values = ConfirmedValues(is_pdo_cob_id)
        self._seen: dict[tuple[int, int], tuple[int, int]] = {}
        """(SDO channel: low 7 bits of its COB-IDs, communication object) -> (COB-ID value, when)."""
        self._booted: dict[int, int] = {}
        """node id -> when its last boot-up came."""
        self._tick = 0
        """Counts what was seen (``when``); unlike the trace's numbers, a monitor reset does not start it again."""

    def observe(self, cob_id: int, data: bytes | bytearray) -> None:
        confirmed = self._values.observe(cob_id, data)
        if confirmed is not None:
            self._tick += 1
            self._seen[(confirmed.channel, confirmed.index)] = (confirmed.value, self._tick)

    def boot(self, node_id: int) -> None:
        self._tick += 1
        self._booted[node_id] = self._tick

    def copy(self) -> tuple[dict[tuple[int, int], tuple[int, int]], dict[int, int]]:
        """The figures to work with outside the lock."""
        return dict(self._seen), dict(self._booted)

    @staticmethod
    def owners(seen: Mapping[tuple[int, int], tuple[int, int]], booted: Mapping[int, int],
               sdo_owners: Mapping[int, tuple[Service, int]], nodes: Mapping[int, SessionNode]) -> dict[int, Owner]:
        """COB-ID -> (service, node) for the PDOs seen (a TPDO before an RPDO on the same COB-ID: the producer's
        node counts), and (UNKNOWN, None) for the defaults they moved away from that no PDO seen uses."""
        used: dict[int, tuple[bool, int, Owner]] = {}
        left: set[int] = set()
        for (channel, index), (value, seq) in seen.items():
            answer = 0x580 + channel
            node_id = sdo_owners[answer][1] if answer in sdo_owners else channel
            if seq < booted.get(node_id, -1):
                continue  # seen before the node's last boot-up: it has loaded its parameters anew
            default = default_cob_id(nodes.get(node_id), node_id, index)
            cob_id = value & 0x7FF
            if default is not None and (value & COB_INVALID or cob_id != default):
                left.add(default)
            if value & COB_INVALID:
                continue
            rank = (index < TPDO_BASE, node_id)
            if cob_id not in used or rank < used[cob_id][:2]:
                used[cob_id] = (*rank, (pdo_service(index), node_id))
        owners: dict[int, Owner] = {cob_id: (Service.UNKNOWN, None) for cob_id in left}
        owners.update((cob_id, owner) for cob_id, (_rpdo, _node, owner) in used.items())
        return owners
