"""Which values read as hexadecimal: words whose digits mean something in hex rather than as an amount.

CiA 301 fixes them for every device: COB-IDs (EMCY, SYNC, TIME, the SDO servers and clients, the PDOs), the device
type, the identity object 0x1018 and the PDO mapping entries (index, subindex, length). A profile marks its own
(``hex: true``, a vendor code holding a COB-ID); bit-coded words (``bits``) are shown in hex with their bit names.
Everything else reads in decimal, with its unit.
"""

from __future__ import annotations

from drivebench.device.profiles.catalog import Item

_WHOLE_OBJECTS = {0x1000, 0x1005, 0x1012, 0x1014, 0x1018}
"""Device type, COB-ID SYNC, COB-ID TIME, COB-ID EMCY, identity (every subindex but the count)."""


def _cia301_hex(index: int, subindex: int) -> bool:
    if subindex == 0 and index != 0x1000 and index != 0x1005 and index != 0x1012 and index != 0x1014:
        return False  # the number of entries of a record or array
    if index in _WHOLE_OBJECTS:
        return True
    if 0x1200 <= index <= 0x12FF:  # SDO server / client parameter: sub 1, 2 are COB-IDs
        return subindex in (1, 2)
    if 0x1400 <= index <= 0x15FF or 0x1800 <= index <= 0x19FF:  # PDO communication parameter: sub 1 the COB-ID
        return subindex == 1
    return 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF  # PDO mapping entries


def shows_hex(item: Item) -> bool:
    """The item's integer value reads in hex (``0x00000185``), not in decimal."""
    entry = item.entry
    if not entry.data_type.is_integer or entry.selection or entry.factor != 1:
        return False
    if entry.bits or getattr(entry, "hex", False):
        return True
    return item.index < 0x2000 and _cia301_hex(item.index, item.subindex)


def hex_word(item: Item, raw: int) -> str:
    """``0x00000185``: as many digits as the data type has (a negative value in two's complement)."""
    return hex_digits(raw, item.entry.data_type.size or 4)


def hex_digits(raw: int, size: int) -> str:
    """``raw`` in hex with ``size`` bytes' digits (``0x0260`` for a status word)."""
    return f"0x{raw & ((1 << size * 8) - 1):0{size * 2}X}"
