"""The ``pdo_rules`` section of a device profile: what the manual says about its PDOs beyond CiA 301.

* ``device_notes``: notes for the whole PDO tab;
* ``pdos``: per PDO its notes, the vendor parameters that shape it (read and shown on its card), and a static
  mapping: what it carries while its mapping count is 0 (CiA 301 reads count 0 as "nothing mapped");
* ``transmission``: transmission types the manual does not permit (or that behave specially), with why;
* ``mapping_bits``: a vendor parameter that keeps one bit per mappable object, so a mapping must list its objects
  in the manual's sequence; the byte a mapping stands for is shown.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivebench.device.profiles.hex_int import HexInt
from drivebench.device.profiles.templates import check_template
from drivebench.i18n import N_, Text

Direction = Literal["rpdo", "tpdo"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PdoRule(_Model):
    direction: Direction
    number: int = Field(ge=1, le=512)
    notes: list[str] = Field(default_factory=list)
    settings: list[str] = Field(default_factory=list)
    """Vendor parameters that shape this PDO beyond its CiA 301 objects (``C00357/1``)."""
    static_mapping: list[str] = Field(default_factory=list)
    """What the PDO carries while its mapping count is 0, as refs (``C00866/1`` ...)."""
    static_mapping_note: str | None = None


class TransmissionRule(_Model):
    direction: Direction | None = None
    """None: both directions."""
    types: list[tuple[int, int]] = Field(min_length=1)
    """Inclusive ranges of transmission types: ``[[252, 253]]``."""
    note: str

    def covers(self, direction: str, trans_type: int) -> bool:
        return self.direction in (None, direction) and any(lo <= trans_type <= hi for lo, hi in self.types)


class SequencedObject(_Model):
    index: HexInt
    subindex: int = Field(0, ge=0, le=255)
    sequence: int = Field(ge=1)
    """Place in the manual's mapping sequence (lowest first; objects with one place are alternatives)."""
    bit: int = Field(ge=0, le=7)
    """Its bit in the selecting byte."""


class SelectingByte(_Model):
    number: int = Field(ge=1, le=512)
    """The PDO whose mapping this byte selects."""
    ref: str
    byte: str
    """Which byte of ``ref`` (``low byte``)."""


class MappingBits(_Model):
    """A vendor parameter that keeps one bit per mappable object of a direction's PDOs."""

    direction: Direction
    objects: list[SequencedObject]
    pdos: list[SelectingByte]
    flag_bit: int | None = Field(None, ge=0, le=7)
    """Set in the byte when an object of ``flag_indices`` is mapped."""
    flag_indices: list[HexInt] = Field(default_factory=list)
    order_text: str
    """Why a mapping out of sequence is refused."""
    exclusive: list[list[HexInt]] = Field(default_factory=list)
    """Groups of indices a mapping must not mix (``exclusive_text`` says why)."""
    exclusive_text: str | None = None
    byte_text: str
    """The byte this mapping stands for: ``{ref}``, ``{byte}``, ``{bits}`` (``this mapping is {ref} {byte} =
    0x{bits:02X}``)."""
    no_bit_text: str
    """An object of the mapping has no bit: ``{ref}``."""

    @model_validator(mode="after")
    def _check_texts(self) -> MappingBits:
        check_template(self.byte_text, {"ref": "P2041", "byte": "low byte", "bits": 0}, "byte_text")
        check_template(self.no_bit_text, {"ref": "P2041"}, "no_bit_text")
        if self.exclusive and not self.exclusive_text:
            raise ValueError(Text(N_("exclusive groups need an exclusive_text")))
        return self


class PdoRules(_Model):
    device_notes: list[str] = Field(default_factory=list)
    pdos: list[PdoRule] = Field(default_factory=list)
    transmission: list[TransmissionRule] = Field(default_factory=list)
    mapping_bits: list[MappingBits] = Field(default_factory=list)

    def pdo(self, direction: str, number: int) -> PdoRule | None:
        return next((r for r in self.pdos if r.direction == direction and r.number == number), None)

    def bits_for(self, direction: str, number: int) -> tuple[MappingBits, SelectingByte] | None:
        for rule in self.mapping_bits:
            if rule.direction == direction:
                for selecting in rule.pdos:
                    if selecting.number == number:
                        return rule, selecting
        return None
