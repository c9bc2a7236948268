"""Parameter references as a user types them, and the families' code <-> index rules.

A reference is either a vendor code (``C00088``, ``C88``, ``88``, ``C00118/3``, ``C00118.3``, ``P2040``,
``r2054.3``) or a CANopen index (``0x5FA7``, ``0x5FA7.0``, ``0x5FA7sub0``, ``5FA7sub0``, ``0x1017``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from drivebench.device.profiles.profile import (
    Addressing,
    CanopenOnlyAddressing,
    CodeAddressing,
    ParameterNumberAddressing,
)
from drivebench.errors import UnknownParameter
from drivebench.i18n import _

_INDEX_RE = re.compile(r"^(?:0x)?([0-9a-f]{4})(?:(?:\.|sub|:|/)(0x)?([0-9a-f]{1,3}))?$", re.IGNORECASE)
_CODE_RE = re.compile(r"^([CPR])?\s*0*(\d{1,5})(?:[./](\d{1,3}))?$", re.IGNORECASE)


@dataclass(frozen=True)
class IndexRef:
    index: int
    subindex: int | None  # None: "the object", i.e. subindex 0 for a VAR


@dataclass(frozen=True)
class CodeRef:
    prefix: str  # "C", "P", "r" or "" when the user typed just a number
    number: int
    subcode: int | None


Ref = IndexRef | CodeRef


def _subindex(hex_prefix: str | None, digits: str | None) -> int | None:
    """The subindex as written after the index: decimal when it is digits only (``0x1A00.10`` is sub 10, the way a
    catalog writes its refs and CiA 306 counts them), hex with ``0x`` or a letter (``0x1A00.0x0A``, ``0x1003.0A``)."""
    if digits is None:
        return None
    value = int(digits, 16) if hex_prefix or not digits.isdigit() else int(digits)
    if value > 0xFF:
        raise UnknownParameter(_("Subindex {sub} is more than 255").format(sub=digits))
    return value


def parse_ref(text: str) -> Ref:
    """Parse what a user typed into a reference. Raises UnknownParameter with the accepted forms."""
    cleaned = text.strip()
    is_hex_index = cleaned.lower().startswith("0x") or "sub" in cleaned.lower() or (
        len(cleaned.split(".")[0]) == 4 and any(c in "abcdefABCDEF" for c in cleaned)
    )
    if is_hex_index:
        match = _INDEX_RE.match(cleaned)
        if match:
            return IndexRef(int(match.group(1), 16), _subindex(match.group(2), match.group(3)))
    match = _CODE_RE.match(cleaned)
    if match:
        prefix = (match.group(1) or "")
        prefix = "r" if prefix == "r" else prefix.upper()
        sub = int(match.group(3)) if match.group(3) is not None else None
        if sub is not None and sub > 0xFF:  # a code's index is the object's sub-index: one byte on the wire
            raise UnknownParameter(_("Subindex {sub} is more than 255").format(sub=match.group(3)))
        return CodeRef(prefix, int(match.group(2)), sub)
    raise UnknownParameter(_("'{text}' is not a parameter reference. Use a vendor code (C00088, C00118/3, P2040, "
                             "r2054.3) or a CANopen index (0x5FA7, 0x5FA7.0, 0x1018sub1).").format(text=text))


def code_to_index(addressing: Addressing, number: int, subcode: int = 0) -> tuple[int, int]:
    """Vendor code number (including a Lenze parameter-set offset, C2011 = C0011 in set 2) -> (index, sub)."""
    if isinstance(addressing, CodeAddressing):
        index = addressing.base - number
        if not addressing.lowest_index <= index <= addressing.base:
            raise UnknownParameter(_("Code C{number} is outside the Lenze code range (index {index}; codes lie "
                                     "between {lowest} and {base})").format(
                                         number=number, index=f"0x{index:04X}",
                                         lowest=f"0x{addressing.lowest_index:04X}", base=f"0x{addressing.base:04X}"))
        return index, subcode
    if isinstance(addressing, ParameterNumberAddressing):
        index = addressing.base + number
        if index in addressing.not_parameters or index > 0x5FFF:
            raise UnknownParameter(_("Parameter {number} is not on the MICROMASTER parameter channel "
                                     "(0x2000..0x2801, 0x2804..0x5FFF)").format(number=number))
        return index, subcode
    raise UnknownParameter(_("This device has no vendor parameter codes; use a CANopen index such as 0x1017"))


def index_to_code(addressing: Addressing, index: int, subindex: int) -> tuple[int, int] | None:
    """(index, sub) -> (code number, subcode), or None where the index is not a vendor parameter."""
    if isinstance(addressing, CodeAddressing):
        number = addressing.base - index
        in_range = 0 <= number <= addressing.base - addressing.lowest_index and index < 0x6000
        return (number, subindex) if in_range else None
    if isinstance(addressing, ParameterNumberAddressing):
        if 0x2000 <= index <= 0x5FFF and index not in addressing.not_parameters:
            return index - addressing.base, subindex
        return None
    if isinstance(addressing, CanopenOnlyAddressing):
        return None
    return None


def code_parameter_set(addressing: Addressing, number: int) -> tuple[int, int]:
    """C2011 -> (11, 2): the base code number and the parameter set (1..4) it addresses."""
    if isinstance(addressing, CodeAddressing) and addressing.set_offset:
        return number % addressing.set_offset, number // addressing.set_offset + 1
    return number, 1


def format_code(addressing: Addressing, prefix: str, number: int) -> str:
    digits = addressing.code_digits if isinstance(addressing, CodeAddressing) else 4  # P2041, r0947
    return f"{prefix}{number:0{digits}d}"
