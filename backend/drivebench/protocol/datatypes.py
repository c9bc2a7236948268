"""CiA 301 data types and their little-endian wire encoding."""

from __future__ import annotations

import struct
from enum import StrEnum


class DataType(StrEnum):
    """CiA 301 data types (names as in CiA 306 EDS files)."""

    BOOLEAN = "BOOLEAN"
    INTEGER8 = "INTEGER8"
    INTEGER16 = "INTEGER16"
    INTEGER24 = "INTEGER24"
    INTEGER32 = "INTEGER32"
    INTEGER64 = "INTEGER64"
    UNSIGNED8 = "UNSIGNED8"
    UNSIGNED16 = "UNSIGNED16"
    UNSIGNED24 = "UNSIGNED24"
    UNSIGNED32 = "UNSIGNED32"
    UNSIGNED64 = "UNSIGNED64"
    REAL32 = "REAL32"
    REAL64 = "REAL64"
    VISIBLE_STRING = "VISIBLE_STRING"
    OCTET_STRING = "OCTET_STRING"
    UNICODE_STRING = "UNICODE_STRING"
    DOMAIN = "DOMAIN"

    @property
    def size(self) -> int | None:
        """Size in bytes on the wire; ``None`` for variable-length types."""
        return _SIZES.get(self)

    @property
    def is_integer(self) -> bool:
        return self.name.startswith(("INTEGER", "UNSIGNED")) or self is DataType.BOOLEAN

    @property
    def is_signed(self) -> bool:
        return self.name.startswith("INTEGER")

    @property
    def is_float(self) -> bool:
        return self in (DataType.REAL32, DataType.REAL64)

    @property
    def is_string(self) -> bool:
        return self in (DataType.VISIBLE_STRING, DataType.OCTET_STRING, DataType.UNICODE_STRING, DataType.DOMAIN)

    def raw_limits(self) -> tuple[int, int] | None:
        """The range a raw integer of this type can hold."""
        if not self.is_integer or self.size is None:
            return None
        if self is DataType.BOOLEAN:
            return (0, 1)
        bits = self.size * 8
        if self.is_signed:
            return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
        return (0, (1 << bits) - 1)

    @property
    def code(self) -> int:
        """The CiA 301 data type index (0x0001 BOOLEAN ... ) used in EDS ``DataType=``."""
        return _CODES[self]


_SIZES = {
    DataType.BOOLEAN: 1, DataType.INTEGER8: 1, DataType.INTEGER16: 2, DataType.INTEGER24: 3, DataType.INTEGER32: 4,
    DataType.INTEGER64: 8, DataType.UNSIGNED8: 1, DataType.UNSIGNED16: 2, DataType.UNSIGNED24: 3,
    DataType.UNSIGNED32: 4, DataType.UNSIGNED64: 8, DataType.REAL32: 4, DataType.REAL64: 8,
}
_CODES = {
    DataType.BOOLEAN: 0x01, DataType.INTEGER8: 0x02, DataType.INTEGER16: 0x03, DataType.INTEGER32: 0x04,
    DataType.UNSIGNED8: 0x05, DataType.UNSIGNED16: 0x06, DataType.UNSIGNED32: 0x07, DataType.REAL32: 0x08,
    DataType.VISIBLE_STRING: 0x09, DataType.OCTET_STRING: 0x0A, DataType.UNICODE_STRING: 0x0B,
    DataType.DOMAIN: 0x0F, DataType.INTEGER24: 0x10, DataType.REAL64: 0x11, DataType.INTEGER64: 0x15,
    DataType.UNSIGNED24: 0x16, DataType.UNSIGNED64: 0x1B,
}
DATA_TYPE_BY_CODE = {code: dt for dt, code in _CODES.items()}


_STRUCT = {
    DataType.BOOLEAN: "<B", DataType.INTEGER8: "<b", DataType.INTEGER16: "<h", DataType.INTEGER32: "<i",
    DataType.INTEGER64: "<q", DataType.UNSIGNED8: "<B", DataType.UNSIGNED16: "<H", DataType.UNSIGNED32: "<I",
    DataType.UNSIGNED64: "<Q", DataType.REAL32: "<f", DataType.REAL64: "<d",
}


def encode(data_type: DataType, raw: int | float | str | bytes) -> bytes:
    """Raw value -> bytes on the wire (CiA 301: little-endian). Raises ValueError if it does not fit."""
    if data_type.is_string:
        if isinstance(raw, bytes):
            return raw
        if data_type is DataType.OCTET_STRING and isinstance(raw, str):
            return bytes.fromhex(raw)
        if data_type is DataType.UNICODE_STRING:
            return str(raw).encode("utf-16-le")
        return str(raw).encode("latin-1")
    if data_type in (DataType.INTEGER24, DataType.UNSIGNED24):
        return int(raw).to_bytes(3, "little", signed=data_type.is_signed)
    fmt = _STRUCT[data_type]
    try:
        return struct.pack(fmt, raw if data_type.is_float else int(raw))
    except struct.error as exc:
        raise ValueError(f"{raw!r} does not fit {data_type.value}") from exc


def decode(data_type: DataType, data: bytes) -> int | float | str | bytes:
    """Bytes on the wire -> raw value. Extra bytes beyond the type's size are ignored."""
    if data_type is DataType.VISIBLE_STRING:
        return data.rstrip(b"\x00").decode("latin-1")
    if data_type is DataType.UNICODE_STRING:
        return data.decode("utf-16-le").rstrip("\x00")
    if data_type.is_string:
        return bytes(data)
    size = data_type.size or len(data)
    if len(data) < size:
        data = data + bytes(size - len(data))  # a device may answer a shorter expedited value
    if data_type in (DataType.INTEGER24, DataType.UNSIGNED24):
        return int.from_bytes(data[:3], "little", signed=data_type.is_signed)
    value = struct.unpack(_STRUCT[data_type], data[:size])[0]
    return value
