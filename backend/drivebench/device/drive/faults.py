"""The ``faults`` section of a device profile: the drive's own fault numbers in words, and what routes its commands.

An EMCY telegram names a CiA 301 class; the drive's own fault number (MICROMASTER F0001, a Lenze error number)
rides in its manufacturer-specific bytes. This section says where (``emcy_number``), how the number reads
(``fields``: bit fields such as the Lenze error type, subject area and ID) and what each number means, with the
manual's remedy and the page it came from (``entries``). ``command_source`` names the parameter that routes commands
to the fieldbus, so a command the drive ignores is explained in words. Every entry names its source; what the
sources did not give is said in ``not_covered``.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from drivebench.device.profiles.hex_int import HexInt


class EmcyNumber(BaseModel):
    """Where an EMCY telegram carries the device's own fault number."""

    model_config = ConfigDict(extra="forbid")

    codes: list[HexInt] = Field(default_factory=list)
    """The EMCY error codes that carry it (empty: every code but 0x0000)."""
    byte: int = Field(ge=3, le=7)
    """First byte of the number in the 8-byte telegram, counted from 0 (bytes 0-1 code, byte 2 error register)."""
    length: int = Field(ge=1, le=4)
    """Bytes, little-endian."""
    source: str | None = None


class NumberField(BaseModel):
    """A bit field of the fault number (Lenze: error type, subject area, error ID)."""

    model_config = ConfigDict(extra="forbid")

    name: str
    shift: int = Field(ge=0, le=31)
    bits: int = Field(ge=1, le=32)
    texts: dict[int, str] = Field(default_factory=dict)
    """Value -> meaning (the Lenze error types)."""


class FaultEntry(BaseModel):
    """One fault number of the manual: its display name, text and remedy, and where they stand."""

    model_config = ConfigDict(extra="forbid")

    number: HexInt
    name: str | None = None
    """The device's display name (F0001, OC1, CE04)."""
    text: str
    remedy: str | None = None
    source: str = Field(min_length=1)
    """Document, edition, page or table."""


class CommandSource(BaseModel):
    """The parameter that says where the drive takes its commands from (MICROMASTER P0700)."""

    model_config = ConfigDict(extra="forbid")

    ref: str
    fieldbus: list[int] = Field(min_length=1)
    """The values that route commands to the fieldbus."""
    source: str = Field(min_length=1)


class FaultsSection(BaseModel):
    """The device's own faults in words (``device/drive/faults.py``)."""

    model_config = ConfigDict(extra="forbid")

    source: str | None = None
    """The documents this section was built from."""
    not_covered: str | None = None
    """What the sources did not give (fault numbers with no text, parameters with no source)."""
    emcy_number: EmcyNumber | None = None
    match_mask: HexInt = 0xFFFFFFFF
    """Bits of the number an entry is matched on (Lenze 8400: the error type is parameterisable, so not it)."""
    label: str = "{number}"
    """How the number is written where no entry names it: ``{number}`` decimal, ``{number:#010x}`` hexadecimal."""
    fields: list[NumberField] = Field(default_factory=list)
    entries: list[FaultEntry] = Field(default_factory=list)
    present: list[str] = Field(default_factory=list)
    """Parameters holding the present fault (MICROMASTER r0947, Lenze C0161)."""
    history: list[str] = Field(default_factory=list)
    """Parameters holding the fault history."""
    command_source: CommandSource | None = None


class DecodedFault(BaseModel):
    """A fault number read from a telegram or a parameter, in words (``None`` fields: the profile has no text)."""

    number: int
    label: str
    text: str | None = None
    remedy: str | None = None
    source: str | None = None
    fields: list[str] = Field(default_factory=list)
    """The number's bit fields in words (``error type: Fault``)."""


def emcy_fault_number(section: FaultsSection, code: int, manufacturer: bytes) -> int | None:
    """The device's fault number in an EMCY telegram's five manufacturer-specific bytes (frame bytes 3-7)."""
    where = section.emcy_number
    if where is None or code == 0 or (where.codes and code not in where.codes):
        return None
    start = where.byte - 3
    raw = bytes(manufacturer[start:start + where.length])
    if len(raw) < where.length:
        return None
    number = int.from_bytes(raw, "little")
    return number or None


def decode_number(section: FaultsSection, number: int) -> DecodedFault:
    entry = next((e for e in section.entries
                  if e.number & section.match_mask == number & section.match_mask), None)
    fields = []
    for field in section.fields:
        value = number >> field.shift & ((1 << field.bits) - 1)
        fields.append(f"{field.name}: {field.texts.get(value, str(value))}")
    label = entry.name if entry and entry.name else section.label.format(number=number)
    return DecodedFault(number=number, label=label, text=entry.text if entry else None,
                        remedy=entry.remedy if entry else None, source=entry.source if entry else None,
                        fields=fields)


def decode_emcy(section: FaultsSection | None, code: int, manufacturer: bytes) -> DecodedFault | None:
    if section is None:
        return None
    number = emcy_fault_number(section, code, manufacturer)
    return None if number is None else decode_number(section, number)
