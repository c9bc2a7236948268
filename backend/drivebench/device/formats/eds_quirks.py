"""The readings the EDS/DCF import applies to what vendors' files really hold, each with a warning.

A commissioning engineer cannot fix a vendor's file on site, so a quirk is read the way the tools in use read it
(python canopen's EDS import, Windows INI readers, CiA 306 where it speaks) and the reading is reported as an
:class:`ImportWarning` naming file, line, key and the reading chosen. Only a file without a usable object
dictionary is refused (:mod:`drivebench.device.formats.eds`).
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass, field

from drivebench.device.profiles.profile import Access, Value
from drivebench.i18n import N_, Text, shown
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE, DataType

MAX_WARNINGS = 500
"""More than this are summed up in one last warning (a file of junk must not make a megabyte of warnings)."""

ACCESS_ALIASES = {"r": Access.RO, "read": Access.RO, "readonly": Access.RO, "read_only": Access.RO,
                  "w": Access.WO, "write": Access.WO, "writeonly": Access.WO, "readwrite": Access.RW,
                  "r/w": Access.RW, "read/write": Access.RW, "c": Access.CONST, "constant": Access.CONST}
OBJECT_TYPE_NAMES = {"var": 0x7, "domain": 0x2, "array": 0x8, "record": 0x9, "deftype": 0x5, "defstruct": 0x6}
# CiA 301 types the model has no field for: read as DOMAIN (bytes), what canopen does with unknown types.
OTHER_TYPE_NAMES = {0x0C: "TIME_OF_DAY", 0x0D: "TIME_DIFFERENCE", 0x0E: "BIT_STRING", 0x12: "INTEGER40",
                    0x13: "INTEGER48", 0x14: "INTEGER56", 0x18: "UNSIGNED40", 0x19: "UNSIGNED48",
                    0x1A: "UNSIGNED56", 0x20: "PDO_COMMUNICATION_PARAMETER", 0x21: "PDO_MAPPING",
                    0x22: "SDO_PARAMETER", 0x23: "IDENTITY"}

_PLAIN_INT = re.compile(r"^\s*([-+]?)(?:0[xX]([0-9a-fA-F]+)|([1-9][0-9]*|0))\s*$")
_INTEGER_LIMITS = {t: t.raw_limits() for t in DataType if t.is_integer and t.raw_limits() is not None}
_NUMBER_HEAD = re.compile(r"^\s*([-+]?\s*(?:0[xX][0-9a-fA-F]+|\d+(?:\.\d*)?(?:[eE][-+]?\d+)?))(.*)$", re.DOTALL)
_TERM = re.compile(r"\s*([-+]?)\s*(\$NODEID|0[xX][0-9a-fA-F]+|\d+)\s*", re.IGNORECASE)


@dataclass(frozen=True)
class ImportWarning:
    """One reading of a quirk: where it is and what was made of it."""

    file: str
    line: int | None
    key: str | None
    message: str
    index: int | None = None
    subindex: int | None = None
    limits: bool = False
    """The object's LowLimit/HighLimit were repaired or dropped: a write of it says so first."""

    def text(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.key + ': ' if self.key else ''}{shown(self.message)}"


@dataclass
class Warnings:
    """The warnings of one import, in file order of discovery, capped at :data:`MAX_WARNINGS`."""

    file: str
    items: list[ImportWarning] = field(default_factory=list)
    dropped: int = 0

    def add(self, line: int | None, key: str | None, message: str, *, address: tuple[int, int] | None = None,
            limits: bool = False) -> None:
        if len(self.items) >= MAX_WARNINGS:
            self.dropped += 1
            return
        index, sub = address if address is not None else (None, None)
        self.items.append(ImportWarning(self.file, line, key, message, index, sub, limits))

    def result(self) -> list[ImportWarning]:
        if not self.dropped:
            return list(self.items)
        return [*self.items, ImportWarning(self.file, None, None, Text(N_("{dropped} more warnings not listed"),
                                                                       dropped=self.dropped))]


# --- numbers ---------------------------------------------------------------------------------------------
def parse_int_strict(text: str) -> int:
    """CiA 306 integer: decimal, 0x hex, or octal with a leading 0. Raises ValueError."""
    cleaned = text.strip().replace(" ", "")
    sign = -1 if cleaned.startswith("-") else 1
    body = cleaned.lstrip("+-")
    if body.lower().startswith("0x"):
        return sign * int(body[2:], 16)
    if len(body) > 1 and body.startswith("0"):
        return sign * int(body[1:], 8)
    if not body.isdigit():
        raise ValueError(Text(N_("{text!r} is not a number"), text=text))
    return sign * int(body)


def read_int(text: str) -> tuple[int, str | None]:
    """A number as vendors write it -> (value, the reading applied or None). Raises ValueError for no number.

    Leading-zero numbers are octal (CiA 306 4.6.3) when their digits allow it; with an 8 or 9 they are decimal.
    Trailing text (``0x180 (COB-ID)``) is ignored, an integral float (``100.0``) is read as the integer."""
    plain = _PLAIN_INT.match(text)
    if plain is not None:  # the common case, fast: decimal without leading zeros or 0x hex
        sign, hex_digits, decimal = plain.groups()
        value = int(hex_digits, 16) if hex_digits is not None else int(decimal)
        return (-value if sign == "-" else value), None
    try:
        return parse_int_strict(text), _octal_note(text)
    except ValueError:
        pass
    head = _NUMBER_HEAD.match(text)
    if head is None:
        raise ValueError(Text(N_("{text!r} is not a number"), text=text.strip()))
    number, rest = head.group(1).replace(" ", ""), head.group(2).strip()
    notes: list[str] = []
    body = number.lstrip("+-")
    if body.isdigit() and body.startswith("0") and len(body) > 1:  # octal digits failed: 8 or 9 inside
        value = int(number, 10)
        notes.append(Text(N_("read as decimal {value}: leading zeros, and 8/9 are no octal digits"), value=value))
    elif body.lower().startswith("0x") or body.isdigit():
        value = parse_int_strict(number)
        note = _octal_note(number)
        if note:
            notes.append(note)
    else:
        as_float = float(number)
        if not as_float.is_integer():
            raise ValueError(Text(N_("{text!r} is not a whole number"), text=text.strip()))
        value = int(as_float)
        notes.append(Text(N_("{number} read as the integer {value}"), number=number, value=value))
    if rest:
        notes.append(Text(N_("text after the number ignored ({value!r})"), value=rest[:40]))
    return value, Text.joined("; ", notes) if notes else None


def _octal_note(text: str) -> str | None:
    body = text.strip().lstrip("+-").replace(" ", "")
    if len(body) > 1 and body.startswith("0") and body.isdigit() and int(body, 8) != int(body, 10):
        return Text(N_("read as octal {octal} (CiA 306: a leading 0 means octal), not decimal {decimal}"),
                    octal=int(body, 8), decimal=int(body, 10))
    return None


def node_expr(text: str) -> int | None:
    """The constant of a ``$NODEID`` formula (``$NODEID+0x180``, ``0x100+$NODEID+0x80`` -> 0x180), None if
    ``text`` has no ``$NODEID``. ``$NODEID`` may stand anywhere in a sum, once and with a plus sign."""
    if "$NODEID" not in text.upper():
        return None
    position, constant, node_terms = 0, 0, 0
    stripped = text.strip()
    while position < len(stripped):
        term = _TERM.match(stripped, position)
        if term is None or (position and not term.group(1)):
            raise ValueError(Text(N_("{text!r} is not a sum of numbers and $NODEID"), text=text))
        sign = -1 if term.group(1) == "-" else 1
        if term.group(2).upper() == "$NODEID":
            if sign < 0:
                raise ValueError(Text(N_("{text!r} subtracts $NODEID"), text=text))
            node_terms += 1
        else:
            constant += sign * parse_int_strict(term.group(2))
        position = term.end()
    if node_terms != 1:
        raise ValueError(Text(N_("{text!r} has $NODEID {count} times"), text=text, count=node_terms))
    return constant


# --- values of a data type ------------------------------------------------------------------------------
def fit_int(data_type: DataType, value: int, *, limit: str | None = None) -> tuple[int | None, str | None]:
    """An integer that does not fit ``data_type`` -> the reading tools apply, or None (dropped), with a note.

    Hex patterns of signed types are two's complement (of the type's width, else of 32 or 64 bits, what tools
    that write every limit as UNSIGNED32 mean); a negative number of an unsigned type is the same bit pattern.
    A limit still outside the type's range is clamped to it (``limit`` names LowLimit/HighLimit)."""
    limits = _INTEGER_LIMITS.get(data_type)
    if limits is None:
        return value, None
    low, high = limits
    if low <= value <= high:
        return value, None
    if data_type.is_signed and value > high:
        for bits in sorted({(data_type.size or 4) * 8, 32, 64}):
            if value < 1 << bits:
                signed = value - (1 << bits) if value >= 1 << (bits - 1) else value
                if low <= signed <= high:
                    return signed, (Text(N_("read as {signed}: the type is {type}, a {bits}-bit two's complement "
                                            "pattern"), signed=signed, type=data_type.value, bits=bits))
    if not data_type.is_signed and value < 0 and data_type is not DataType.BOOLEAN:
        pattern = value + (high + 1)
        if 0 <= pattern <= high and limit is None:
            return pattern, Text(N_("read as 0x{pattern:X}: the type is {type}, the same bit pattern"),
                                 pattern=pattern, type=data_type.value)
    if limit is not None:
        clamped = high if value > high else low
        return clamped, Text(N_("{value} does not fit {type} ({low}..{high}): read as {clamped}"), value=value,
                             type=data_type.value, low=low, high=high, clamped=clamped)
    return None, Text(N_("{value} does not fit {type} ({low}..{high}): dropped"), value=value, type=data_type.value,
                      low=low, high=high)


def read_value(data_type: DataType, text: str, *, limit: str | None = None) -> tuple[Value | None, str | None]:
    """An EDS value of ``data_type`` -> (raw model value or None when unusable, the reading applied or None)."""
    if data_type in (DataType.VISIBLE_STRING, DataType.UNICODE_STRING):
        return text, None
    if data_type in (DataType.OCTET_STRING, DataType.DOMAIN):
        try:
            bytes.fromhex(text)
        except ValueError:
            return None, Text(N_("not hexadecimal bytes: dropped (the file keeps it)"))
        return text, None
    if data_type.is_float:
        return _read_float(data_type, text)
    if data_type is DataType.BOOLEAN and text.strip().lower() in ("true", "false"):
        return int(text.strip().lower() == "true"), None
    try:  # the integers, and a BOOLEAN written as a number
        number, note = read_int(text)
    except ValueError as exc:
        return None, Text(N_("{reason}: dropped"), reason=exc.args[0])
    value, fit_note = fit_int(data_type, number, limit=limit)
    return value, _joined(note, fit_note)


def _joined(*notes: str | None) -> str | None:
    given = [note for note in notes if note]
    return Text.joined("; ", given) if given else None


def _read_float(data_type: DataType, text: str) -> tuple[Value | None, str | None]:
    cleaned = text.strip()
    if cleaned.lower().startswith("0x"):  # some tools write the IEEE 754 bit pattern
        try:
            bits = parse_int_strict(cleaned)
            if data_type is DataType.REAL32:
                return struct.unpack("<f", bits.to_bytes(4, "little"))[0], None
            return struct.unpack("<d", bits.to_bytes(8, "little"))[0], None
        except (ValueError, OverflowError):
            return None, Text(N_("{text!r} is not a {type} bit pattern: dropped"), text=cleaned,
                              type=data_type.value)
    note = None
    if "," in cleaned and "." not in cleaned:
        cleaned, note = cleaned.replace(",", "."), Text(N_("decimal comma read as a point"))
    head = _NUMBER_HEAD.match(cleaned)
    try:
        value = float(cleaned)
    except ValueError:
        if head is None:
            return None, Text(N_("{text!r} is not a number: dropped"), text=text.strip())
        value = float(head.group(1).replace(" ", ""))
        note = Text(N_("text after the number ignored ({value!r})"), value=head.group(2).strip()[:40])
    if not math.isfinite(value):
        return None, Text(N_("{text!r} is not a finite number: dropped"), text=text.strip())
    return value, note


def read_access(text: str) -> tuple[Access, str | None]:
    cleaned = text.strip().lower().replace(" ", "")
    try:
        return Access(cleaned), None
    except ValueError:
        pass
    if cleaned in ACCESS_ALIASES:
        return ACCESS_ALIASES[cleaned], Text(N_("read as {value}"), value=ACCESS_ALIASES[cleaned].value)
    return Access.RO, Text(N_("not ro, wo, rw, rwr, rww or const: read as ro (nothing is written to it)"))


def type_name(code: int) -> str:
    known = DATA_TYPE_BY_CODE.get(code)
    return known.value if known else OTHER_TYPE_NAMES.get(code, Text(N_("no CiA 301 basic data type")))
