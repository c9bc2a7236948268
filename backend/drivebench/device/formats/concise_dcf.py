"""Concise DCF (CiA 302-3, the format of object 0x1F22): the values a master writes to one node, as one byte string.

Layout, little endian: ``U32`` number of entries, then per entry ``U16`` index, ``U8`` sub-index, ``U32`` size of the
data in bytes and the data itself (the object's value as an SDO download sends it).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass

from drivebench.errors import InvalidValue
from drivebench.i18n import _

_COUNT = struct.Struct("<I")
_HEAD = struct.Struct("<HBI")


@dataclass(frozen=True)
class ConciseEntry:
    index: int
    subindex: int
    data: bytes


def encode(entries: Iterable[ConciseEntry]) -> bytes:
    """The concise DCF of ``entries`` in their order."""
    listed = list(entries)
    parts = [_COUNT.pack(len(listed))]
    for entry in listed:
        parts.append(_HEAD.pack(entry.index, entry.subindex, len(entry.data)))
        parts.append(entry.data)
    return b"".join(parts)


def decode(data: bytes) -> list[ConciseEntry]:
    """The entries of a concise DCF; a truncated or over-long one is refused in words (where it breaks)."""
    if len(data) < _COUNT.size:
        raise InvalidValue(_("Not a concise DCF: {size} bytes, the entry count alone takes 4.").format(size=len(data)))
    (count,) = _COUNT.unpack_from(data)
    entries: list[ConciseEntry] = []
    at = _COUNT.size
    for number in range(1, count + 1):
        if at + _HEAD.size > len(data):
            raise InvalidValue(_("Concise DCF ends at byte {at} inside the header of entry {number} of {count}.")
                               .format(at=at, number=number, count=count))
        index, subindex, size = _HEAD.unpack_from(data, at)
        at += _HEAD.size
        if at + size > len(data):
            raise InvalidValue(_("Concise DCF entry {number} (0x{index:04X} sub {sub}) announces {size} bytes; "
                                 "only {left} follow.").format(number=number, index=index, sub=subindex, size=size,
                                                               left=len(data) - at))
        entries.append(ConciseEntry(index, subindex, data[at:at + size]))
        at += size
    if at != len(data):
        raise InvalidValue(_("Concise DCF has {extra} bytes after its {count} entries.").format(
            extra=len(data) - at, count=count))
    return entries
