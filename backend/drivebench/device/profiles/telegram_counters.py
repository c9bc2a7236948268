"""A device's own telegram counters as its profile describes them (8400 motec / BaseLine C: C00360/1..12).

A profile has device counters when it lists parameters named "... telegram counter ..."; each subcode's name says
what it counts (``Telegram counter SDO1 IN``, ``All PDOs/SDOs sent``), which maps onto COB-IDs of the predefined
connection set seen from the device: CAN1 = PDO1, CAN2 = PDO2, SDO1 = 0x600/0x580 + node, SDO2 = 0x640/0x5C0 + node
(manual 8400 motec CANopen, ch. 5 COB-ID table). Read by the monitor's comparison and by the simulated drives.
"""

from __future__ import annotations

import re

from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.profile import Parameter

_CHANNEL = re.compile(r"\b(CAN[12]|SDO[12])[ _](IN|OUT)\b", re.IGNORECASE)
_CHANNEL_COB_BASES = {("CAN1", "OUT"): 0x180, ("CAN2", "OUT"): 0x280, ("CAN1", "IN"): 0x200,
                      ("CAN2", "IN"): 0x300, ("SDO1", "OUT"): 0x580, ("SDO2", "OUT"): 0x5C0,
                      ("SDO1", "IN"): 0x600, ("SDO2", "IN"): 0x640}


def counter_parameters(catalog: Catalog) -> list[Item]:
    """The telegram counter parameters of a profile's catalog (reserved subcodes left out)."""
    return [item for item in catalog.items
            if isinstance(item.entry, Parameter) and "telegram counter" in item.entry.name.lower()
            and (item.entry.subcode_name or "").lower() != "reserved"]


def counted_cob_ids(item: Item, node_id: int) -> list[int] | None:
    """The COB-IDs a device counter parameter counts (from its subcode name), None if the name says nothing."""
    return cob_ids_for(counter_label(item), node_id)


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


def counter_label(item: Item) -> str:
    """What a counter parameter is called where it says what it counts (its subcode name, else its name)."""
    entry = item.entry
    return entry.subcode_name if isinstance(entry, Parameter) and entry.subcode_name else entry.name
