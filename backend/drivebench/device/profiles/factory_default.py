"""The value a device holds from the factory: the profile's default (engineering units, scaled to raw), a CiA 306
``$NODEID`` formula resolved for the node, or CiA 301's pre-defined connection set for the COB-IDs a profile gives
no default. None where no source gives one: such a parameter has no known factory value (never a guess)."""

from __future__ import annotations

import math

from drivebench.device.formats.eds import resolve_node_expr
from drivebench.device.profiles.profile import Entry
from drivebench.device.profiles.scaling import RawValue
from drivebench.protocol.datatypes import DataType

PREDEFINED_CONNECTION_SET = {
    (0x1014, 0): 0x80, (0x1200, 1): 0x600, (0x1200, 2): 0x580,
    (0x1400, 1): 0x200, (0x1401, 1): 0x300, (0x1402, 1): 0x400, (0x1403, 1): 0x500,
    (0x1800, 1): 0x180, (0x1801, 1): 0x280, (0x1802, 1): 0x380, (0x1803, 1): 0x480,
}
"""CiA 301 7.3.5: the COB-ID offsets of EMCY, SDO1 and the first four RPDOs/TPDOs (plus the node id)."""


def factory_raw(entry: Entry, node_id: int, index: int, subindex: int) -> RawValue | None:
    """The raw value the device holds from the factory, None when no source gives one."""
    value = entry.default
    data_type = entry.data_type
    if value is None:
        formula = getattr(entry, "default_expr", None)
        if isinstance(formula, str):
            try:
                return resolve_node_expr(formula, node_id)
            except ValueError:
                return None
        offset = PREDEFINED_CONNECTION_SET.get((index, subindex))
        return None if offset is None or not data_type.is_integer else offset + node_id
    if data_type.is_string:
        if data_type in (DataType.VISIBLE_STRING, DataType.UNICODE_STRING):
            return str(value)
        try:
            return bytes.fromhex(str(value).replace(" ", ""))
        except ValueError:
            return None
    if isinstance(value, str):
        try:
            value = int(value.strip(), 0)
        except ValueError:
            return None
    if not isinstance(value, (int, float)):
        return None
    if data_type.is_float:
        return float(value) * float(entry.factor)
    return round(float(value) * float(entry.factor)) if entry.factor != 1 else int(value)


def same_raw(a: RawValue, b: RawValue) -> bool:
    """Two raw values are the same setting (floats to 1e-6, strings without trailing NULs, bytes as hex)."""
    if isinstance(a, bytes):
        a = a.hex()
    if isinstance(b, bytes):
        b = b.hex()
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
        return False
    if isinstance(a, str) and isinstance(b, str):
        return a.rstrip("\x00") == b.rstrip("\x00")
    return a == b
