"""What the manuals say about a device's PDOs beyond CiA 301, read from its profile's ``pdo_rules`` section
(:mod:`drivebench.device.profiles.pdo_rules`): notes, permitted transmission types, static mappings, the vendor
parameters that shape a PDO and the mapping sequence a selecting byte imposes. Texts for the PDO tab and checks for
:func:`drivebench.services.pdos.pdo.check_mapping`.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

from drivebench.device.profiles.pdo_rules import MappingBits, PdoRule
from drivebench.device.profiles.profile import Profile


def _rule(profile: Profile, direction: str, number: int) -> PdoRule | None:
    return profile.pdo_rules.pdo(direction, number) if profile.pdo_rules else None


def device_notes(profile: Profile) -> list[str]:
    """Notes for the whole PDO tab of a device."""
    return list(profile.pdo_rules.device_notes) if profile.pdo_rules else []


def static_mapping(profile: Profile, direction: str, number: int) -> list[str]:
    """What a PDO carries while its mapping count is 0, as refs; empty where count 0 means nothing is mapped."""
    rule = _rule(profile, direction, number)
    return list(rule.static_mapping) if rule else []


def static_mapping_note(profile: Profile, direction: str, number: int) -> str | None:
    rule = _rule(profile, direction, number)
    return rule.static_mapping_note if rule else None


def pdo_notes(profile: Profile, direction: str, number: int) -> list[str]:
    """Notes for one PDO (its port, its monitoring, its fixed mapping, its selecting byte)."""
    rule = _rule(profile, direction, number)
    return list(rule.notes) if rule else []


def setting_refs(profile: Profile, direction: str, number: int) -> list[str]:
    """Vendor parameters that shape this PDO beyond its CiA 301 objects (read and shown on its card)."""
    rule = _rule(profile, direction, number)
    return list(rule.settings) if rule else []


def transmission_note(profile: Profile, direction: str, trans_type: int) -> str | None:
    """Where the manual says this type is not permitted (or behaves specially) for the device."""
    rules = profile.pdo_rules.transmission if profile.pdo_rules else []
    return next((rule.note for rule in rules if rule.covers(direction, trans_type)), None)


def _bits(profile: Profile, direction: str, number: int) -> MappingBits | None:
    found = profile.pdo_rules.bits_for(direction, number) if profile.pdo_rules else None
    return found[0] if found else None


def mapping_bits_note(profile: Profile, direction: str, number: int,
                      entries: Sequence[tuple[int, int]]) -> str | None:
    """The selecting byte this mapping stands for, in words (MICROMASTER P2041.02/.03), or None."""
    found = profile.pdo_rules.bits_for(direction, number) if profile.pdo_rules else None
    if found is None:
        return None
    rule, selecting = found
    bits = selecting_byte(rule, entries)
    if bits is None:
        return rule.no_bit_text.format(ref=selecting.ref)
    return rule.byte_text.format(ref=selecting.ref, byte=selecting.byte, bits=bits)


def mapping_rule_violation(profile: Profile, direction: str, number: int,
                           entries: Sequence[tuple[int, int]]) -> str | None:
    """A device rule the mapping breaks (in words), or None."""
    rule = _bits(profile, direction, number)
    if rule is None:
        return None
    order = {(o.index, o.subindex): o.sequence for o in rule.objects}
    sequence = [order[entry] for entry in entries if entry in order]
    if any(after <= before for before, after in pairwise(sequence)):
        return rule.order_text
    indices = {index for index, _ in entries}
    if sum(1 for group in rule.exclusive if indices & set(group)) > 1:
        return rule.exclusive_text
    return None


def in_mapping_sequence(profile: Profile, direction: str, number: int,
                        entries: Sequence[tuple[int, int]]) -> list[tuple[int, int]] | None:
    """The entries in the order the device's mapping sequence needs (objects without a place last, in their order),
    or None where the profile names no sequence for this PDO."""
    rule = _bits(profile, direction, number)
    if rule is None:
        return None
    order = {(o.index, o.subindex): o.sequence for o in rule.objects}
    return sorted(entries, key=lambda entry: order.get(entry, len(order) + 1))


def selecting_byte(rule: MappingBits, entries: Sequence[tuple[int, int]]) -> int | None:
    """The byte that selects this mapping, or None where an object has no bit."""
    bits = {(o.index, o.subindex): o.bit for o in rule.objects}
    value = 0
    for entry in entries:
        if entry not in bits:
            return None
        value |= 1 << bits[entry]
        if rule.flag_bit is not None and entry[0] in rule.flag_indices:
            value |= 1 << rule.flag_bit
    return value
