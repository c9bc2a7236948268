"""The device's own telegram counters beside the monitor's counts (8400 motec / BaseLine C: C00360/1..12).

A profile has device counters when it lists parameters named "... telegram counter ..."; each subcode's name says
what it counts (``Telegram counter SDO1 IN``, ``All PDOs/SDOs sent``), which maps onto COB-IDs of the predefined
connection set seen from the device: CAN1 = PDO1, CAN2 = PDO2, SDO1 = 0x600/0x580 + node, SDO2 = 0x640/0x5C0 + node
(manual 8400 motec CANopen, ch. 5 COB-ID table). The device counts since power-up in 16 bits and wraps, the monitor
since its reset: the comparable figures are the increases between two reads, so each read also reports the
increase on both sides since the previous read.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from typing import Any

from drivebench.device.catalog import Catalog, Item
from drivebench.device.profile import Parameter
from drivebench.errors import NotFound
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import Monitor

WRAP = 1 << 16
_CHANNEL = re.compile(r"\b(CAN[12]|SDO[12])[ _](IN|OUT)\b", re.IGNORECASE)
_CHANNEL_COB_BASES = {("CAN1", "OUT"): 0x180, ("CAN2", "OUT"): 0x280, ("CAN1", "IN"): 0x200,
                      ("CAN2", "IN"): 0x300, ("SDO1", "OUT"): 0x580, ("SDO2", "OUT"): 0x5C0,
                      ("SDO1", "IN"): 0x600, ("SDO2", "IN"): 0x640}


def counter_items(session: Session, node_id: int) -> list[Item]:
    """The profile's telegram counter parameters of a node (reserved subcodes left out)."""
    catalog = session.node(node_id).catalog
    return counter_parameters(catalog) if catalog is not None else []


def counter_parameters(catalog: Catalog) -> list[Item]:
    """The telegram counter parameters of a profile's catalog (reserved subcodes left out)."""
    return [item for item in catalog.items
            if isinstance(item.entry, Parameter) and "telegram counter" in item.entry.name.lower()
            and (item.entry.subcode_name or "").lower() != "reserved"]


def counted_cob_ids(item: Item, node_id: int) -> list[int] | None:
    """The COB-IDs a device counter parameter counts (from its subcode name), None if the name says nothing."""
    return cob_ids_for(_label(item), node_id)


def cob_ids_for(label: str, node_id: int) -> list[int] | None:
    """The COB-IDs a device counter counts, from its name; None if the name says nothing we can map."""
    match = _CHANNEL.search(label)
    if match:
        return [_CHANNEL_COB_BASES[(match[1].upper(), match[2].upper())] + node_id]
    lowered = label.lower()
    if "sent" in lowered:
        return [base + node_id for (_, direction), base in _CHANNEL_COB_BASES.items() if direction == "OUT"]
    if "received" in lowered:
        return [base + node_id for (_, direction), base in _CHANNEL_COB_BASES.items() if direction == "IN"]
    return None


def _label(item: Item) -> str:
    entry = item.entry
    return entry.subcode_name if isinstance(entry, Parameter) and entry.subcode_name else entry.name


@dataclass
class _Previous:
    at: float
    device: dict[str, int]
    monitor: dict[str, int]


_previous: dict[tuple[str, int], _Previous] = {}


async def compare(session: Session, monitor: Monitor, node_id: int) -> dict[str, Any]:
    """Read the node's telegram counters via SDO and put them beside the monitor's counts."""
    items = counter_items(session, node_id)
    if not items:
        node = session.node(node_id)
        raise NotFound(f"The profile of node {node_id} ({node.device_name}) has no telegram counters")
    client = session.client(node_id)
    device: dict[str, int] = {}
    for item in items:
        raw = await client.aupload(item.index, item.subindex)
        device[item.ref] = int.from_bytes(raw[:2], "little")
    # The monitor's counts after the reads, so both include the read requests themselves up to the last answer.
    mapping = {item.ref: cob_ids_for(_label(item), node_id) for item in items}
    counted = {ref: monitor.counts_for(cobs) for ref, cobs in mapping.items() if cobs is not None}
    now = time.time()
    previous = _previous.get((session.id, node_id))
    _previous[(session.id, node_id)] = _Previous(now, device, counted)
    rows = []
    for item in items:
        label = _label(item)
        cobs = mapping[item.ref]
        row: dict[str, Any] = {
            "ref": item.ref, "label": label, "device": device[item.ref],
            "cob_ids": [f"0x{c:03X}" for c in cobs] if cobs else [],
            "monitor": counted.get(item.ref), "monitor_wrapped": counted[item.ref] % WRAP
            if item.ref in counted else None, "device_increase": None, "monitor_increase": None}
        if previous is not None and item.ref in previous.device:
            row["device_increase"] = (device[item.ref] - previous.device[item.ref]) % WRAP
            if item.ref in counted and item.ref in previous.monitor:
                row["monitor_increase"] = counted[item.ref] - previous.monitor[item.ref]
        rows.append(row)
    return {"node": node_id, "time": now, "previous_time": previous.at if previous else None, "rows": rows}
