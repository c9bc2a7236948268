"""The COB-IDs a node uses: COB-ID = basic identifier + node id (NMT and SYNC have no node part).

Per family: which services exist, their base identifiers and whether they are on in the factory setting. PDO
identifiers come in two flavours on the 8400 motec (C00353): the CANopen predefined connection set, and the
Lenze base identifiers, which differ only in RPDO2 (0x281 instead of 0x300, 8400 motec manual §7.1.1).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, computed_field

from drivebench.device.dip import LENZE_8400_MOTEC, LENZE_EMF2178IB, SIEMENS_MM4, family_spec
from drivebench.errors import InvalidValue, OutOfRange

PdoIds = Literal["canopen", "lenze"]
Direction = Literal["to node", "from node", "broadcast"]


class Service(BaseModel):
    """One row of a family's identifier table."""

    name: str
    """``TPDO1``, ``SDO1 rx`` ... (rx/tx from the node's point of view: rx = client -> server)."""
    channel: str
    """What a planner switches on or off: ``sdo2``, ``pdo1`` ... (or ``nmt``, ``sync``, ``emcy``,
    ``heartbeat``)."""
    base: int
    direction: Direction
    node_specific: bool = True
    default_on: bool = True
    lenze_base: int | None = None
    """Base identifier when the Lenze base IDs are selected (C00353 = 0), where it differs."""
    source: str = ""


class CobId(BaseModel):
    service: str
    channel: str
    cob_id: int
    direction: Direction
    base: int
    node_specific: bool
    default_on: bool
    source: str
    note: str | None = None

    @computed_field  # type: ignore[prop-decorator]
    @property
    def hex(self) -> str:
        return f"0x{self.cob_id:03X}"


_S8400 = "8400 motec manual §7.1.1"
_SEMF = "EMF2178IB manual §8.1"
_SMM4 = "MICROMASTER manual §3 object table"


def _common(source: str) -> list[Service]:
    return [
        Service(
            name="NMT", channel="nmt", base=0x000, direction="to node", node_specific=False, source=source
        ),
        Service(
            name="SYNC", channel="sync", base=0x080, direction="broadcast", node_specific=False, source=source
        ),
        Service(name="EMCY", channel="emcy", base=0x080, direction="from node", source=source),
    ]


def _tail(source: str) -> list[Service]:
    return [
        Service(name="SDO1 tx", channel="sdo1", base=0x580, direction="from node", source=source),
        Service(name="SDO1 rx", channel="sdo1", base=0x600, direction="to node", source=source),
    ]


_HEARTBEAT = "heartbeat"

SERVICES: dict[str, list[Service]] = {
    LENZE_8400_MOTEC: [
        *_common(_S8400),
        Service(name="TPDO1", channel="pdo1", base=0x180, direction="from node", source=_S8400),
        Service(name="RPDO1", channel="pdo1", base=0x200, direction="to node", source=_S8400),
        Service(name="TPDO2", channel="pdo2", base=0x280, direction="from node", source=_S8400),
        Service(
            name="RPDO2", channel="pdo2", base=0x300, lenze_base=0x281, direction="to node", source=_S8400
        ),
        *_tail(_S8400),
        # SDO2: I-1201 / C00366 = 1; off in the Lenze setting (C00366, I-1201 default 0x80000000).
        Service(
            name="SDO2 tx",
            channel="sdo2",
            base=0x5C0,
            direction="from node",
            default_on=False,
            source=_S8400 + ", I-1201",
        ),
        Service(
            name="SDO2 rx",
            channel="sdo2",
            base=0x640,
            direction="to node",
            default_on=False,
            source=_S8400 + ", I-1201",
        ),
        Service(
            name="Heartbeat / boot-up", channel=_HEARTBEAT, base=0x700, direction="from node", source=_S8400
        ),
    ],
    LENZE_EMF2178IB: [
        *_common(_SEMF),
        Service(name="TPDO1", channel="pdo1", base=0x180, direction="from node", source=_SEMF),
        Service(name="RPDO1", channel="pdo1", base=0x200, direction="to node", source=_SEMF),
        # §8.1 lists PDO2/PDO3 with the predefined basic identifiers like PDO1 (only SDO2 is marked "Lenze
        # setting: not active"), and their validity codes C1865/3, /4 default to valid: on by default.
        Service(name="TPDO2", channel="pdo2", base=0x280, direction="from node", source=_SEMF),
        Service(name="RPDO2", channel="pdo2", base=0x300, direction="to node", source=_SEMF),
        Service(name="TPDO3", channel="pdo3", base=0x380, direction="from node", source=_SEMF),
        Service(name="RPDO3", channel="pdo3", base=0x400, direction="to node", source=_SEMF),
        *_tail(_SEMF),
        # SDO2 = "address + 64" (§7): activated with C1865/1 or C2365/1.
        Service(
            name="SDO2 tx",
            channel="sdo2",
            base=0x5C0,
            direction="from node",
            default_on=False,
            source=_SEMF + ", §7 (address + 64)",
        ),
        Service(
            name="SDO2 rx",
            channel="sdo2",
            base=0x640,
            direction="to node",
            default_on=False,
            source=_SEMF + ", §7 (address + 64)",
        ),
        Service(
            name="Heartbeat / guarding / boot-up",
            channel=_HEARTBEAT,
            base=0x700,
            direction="from node",
            source=_SEMF,
        ),
    ],
    SIEMENS_MM4: [
        *_common(_SMM4),
        Service(name="TPDO1", channel="pdo1", base=0x180, direction="from node", source=_SMM4),
        Service(name="RPDO1", channel="pdo1", base=0x200, direction="to node", source=_SMM4),
        Service(name="TPDO5", channel="pdo5", base=0x280, direction="from node", source=_SMM4),
        Service(name="RPDO5", channel="pdo5", base=0x300, direction="to node", source=_SMM4),
        Service(name="TPDO6", channel="pdo6", base=0x380, direction="from node", source=_SMM4),
        Service(name="RPDO6", channel="pdo6", base=0x400, direction="to node", source=_SMM4),
        *_tail(_SMM4),
        Service(
            name="Heartbeat / guarding / boot-up",
            channel=_HEARTBEAT,
            base=0x700,
            direction="from node",
            source=_SMM4,
        ),
    ],
}

NOTES: dict[str, list[str]] = {
    LENZE_8400_MOTEC: [
        "§7.1.1: the EMCY and SYNC base identifiers are both 0x80 — if you set the sync identifier manually, "
        "mind the emergency telegram, which has the same COB-ID.",
        "§7.1.1: with the Lenze base IDs (C00353 = 0) RPDO2 = 0x281 + node id, which is the TPDO2 of node id "
        "+ 1.",
        "SDO2 (0x640/0x5C0 + node id) is off in the Lenze setting; on with C00366 = 1 or I-1201 bit 31 = 0.",
    ],
    LENZE_EMF2178IB: [
        "§7: SDO2 is reached under node address + 64: its COB-IDs are the SDO1 COB-IDs of node id + 64, so "
        "that node id must stay free (and a node above 63 cannot use SDO2).",
        "§8.1 lists PDO2/PDO3 on the predefined identifiers and the profiles hold them valid (C1865/3, /4 = 1), "
        "so they are on here. §9.1: 'depending on the basic device used, up to 3 RPDOs and TPDOs can be "
        "available'; the 8200 vector's 3 and the 93XX's 4 AIF words fit into PDO1 (§9.3.2). A copy of p. 109 "
        "from outside the seed text says I-1401/I-1402 are not available with 8200 vector and 93XX.",
    ],
    SIEMENS_MM4: [
        "Only PDO1, PDO5 and PDO6 exist; their default COB-IDs are those of the predefined connection set's "
        "PDO1, PDO2 and PDO3.",
    ],
}


def services(family: str) -> list[Service]:
    return SERVICES[family_spec(family).key]


def cob_ids(
    family: str, node_id: int, *, pdo_ids: PdoIds = "canopen", channels: set[str] | None = None
) -> list[CobId]:
    """Every COB-ID ``node_id`` uses; with ``channels``, only those plus NMT/SYNC/EMCY/heartbeat."""
    spec = family_spec(family)
    lo, hi = (
        spec.code_node_range
        if spec.switch_node_range is None
        else (
            min(spec.code_node_range[0], spec.switch_node_range[0]),
            max(spec.code_node_range[1], spec.switch_node_range[1]),
        )
    )
    if not lo <= node_id <= hi:
        raise OutOfRange(f"{spec.name}: node id {node_id} is outside {lo} … {hi}.")
    if pdo_ids == "lenze" and spec.key != LENZE_8400_MOTEC:
        raise InvalidValue(
            f"{spec.name}: Lenze base identifiers are only defined for the 8400 motec here; "
            "use the CANopen identifiers."
        )
    result = []
    for svc in services(spec.key):
        if channels is not None and svc.channel not in channels | {"nmt", "sync", "emcy", _HEARTBEAT}:
            continue
        base = svc.lenze_base if pdo_ids == "lenze" and svc.lenze_base is not None else svc.base
        note = None
        if svc.lenze_base is not None:
            note = (
                f"Lenze base ID 0x{svc.lenze_base:03X} (C00353 = 0) / CANopen 0x{svc.base:03X} "
                "(C00353 = 1, Lenze setting)"
            )
        if svc.channel == "sdo2":
            note = f"= SDO1 COB-ID of node id {node_id + 64}"
        result.append(
            CobId(
                service=svc.name,
                channel=svc.channel,
                cob_id=base + (node_id if svc.node_specific else 0),
                direction=svc.direction,
                base=base,
                node_specific=svc.node_specific,
                default_on=svc.default_on,
                source=svc.source,
                note=note,
            )
        )
    return result


def channels_of(family: str) -> list[str]:
    """Switchable channels of a family in table order (``sdo1``, ``pdo1``, ``pdo2``, ``sdo2`` ...)."""
    seen: list[str] = []
    for svc in services(family):
        if svc.channel not in ("nmt", "sync", "emcy", _HEARTBEAT) and svc.channel not in seen:
            seen.append(svc.channel)
    return seen


def default_channels(family: str) -> set[str]:
    return {s.channel for s in services(family) if s.default_on} - {"nmt", "sync", "emcy", _HEARTBEAT}
