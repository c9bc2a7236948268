"""DIP-switch calculator: node address and baud rate from a device's switch block, and back.

The device is a profile's ``switches`` section (``device/calculators/switches.py``): its switches, the manual's
baud-rate table, the parameters that take over when the switches say so and the rules quoted from the manual. ``decode``
reads switch positions the way the device reads them at switch-on; ``encode`` gives the switch positions for a
node id and baud rate, together with the parameter values that set the same thing without switches. A device
without switches gets its node id and baud rate from parameters only.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from pydantic import BaseModel, Field

from drivebench.device.calculators.switches import Case, SwitchesSection
from drivebench.device.profiles.profile import Profile
from drivebench.errors import InvalidValue, OutOfRange, UnknownProfile
from drivebench.i18n import N_, _


@dataclass(frozen=True)
class SwitchDevice:
    """A device the calculator knows: a ``switches`` section and the profiles that carry it."""

    spec: SwitchesSection
    profile_ids: tuple[str, ...]
    vendor_id: int | None
    """0x1018sub1 a scan should read (the profiles' identity), None when they do not say."""


class SwitchDevices:
    """The devices of the loaded profiles that have a ``switches`` section, one per ``key``.

    Profiles of one module carry the same key and the same section; a later profile whose section under a taken
    key or name differs is left out and named in ``conflicts`` (an upload is refused before: ``clash``)."""

    def __init__(self, profiles: Iterable[Profile]) -> None:
        self._devices: dict[str, SwitchDevice] = {}
        self._names: dict[str, str] = {}
        self.conflicts: list[str] = []
        for profile in profiles:
            spec = profile.switches
            if spec is None:
                continue
            known = self._devices.get(spec.key)
            if known is None and not any(name in self._names for name in _names(spec)):
                self._devices[spec.key] = SwitchDevice(spec, (profile.id,), profile.identity.vendor_id)
                self._names.update(dict.fromkeys(_names(spec), spec.key))
            elif known is not None and known.spec == spec:
                vendor = known.vendor_id if known.vendor_id == profile.identity.vendor_id else None
                self._devices[spec.key] = SwitchDevice(spec, (*known.profile_ids, profile.id), vendor)
            else:
                self.conflicts.append(profile.id)
                continue
            self._names[profile.id.lower()] = spec.key

    def all(self) -> list[SwitchDevice]:
        return [self._devices[key] for key in sorted(self._devices)]

    def find(self, name: str) -> SwitchDevice | None:
        """By key, alias or the id of a profile that carries the section (case does not matter)."""
        key = self._names.get(name.strip().lower())
        return None if key is None else self._devices[key]

    def get(self, name: str) -> SwitchDevice:
        device = self.find(name)
        if device is None:
            raise UnknownProfile(_("No switch/addressing data for device '{name}' (no loaded profile has a "
                                   "'switches' section of that name). Known devices: {known}.").format(
                                       name=name, known=", ".join(self._devices) or _("none")))
        return device


def _names(spec: SwitchesSection) -> set[str]:
    return {spec.key, *(alias.strip().lower() for alias in spec.aliases)}


def clash(profile: Profile, others: Iterable[Profile]) -> str | None:
    """Why ``profile``'s switches section cannot join ``others`` (a key or name another device holds with a
    different section), or None."""
    spec = profile.switches
    if spec is None:
        return None
    for other in others:
        theirs = other.switches
        if other.id == profile.id or theirs is None or theirs == spec:
            continue
        shared = _names(spec) & _names(theirs)
        if shared:
            return _("switches: the name(s) {names} belong to the switch block of profile '{profile}', which "
                     "differs; give this switch block another key and aliases").format(
                         names=", ".join(sorted(shared)), profile=other.id)
    return None


class ParameterSetting(BaseModel):
    """A parameter value that sets node id or baud rate without switches."""

    code: str
    value: int | None
    meaning: str
    note: str | None = None


class DipResult(BaseModel):
    family: str
    """The device's key."""
    switches: dict[str, bool]
    address_switch_sum: int
    """Sum of the weights of the ON address switches."""
    baud_switch_kbit: int | None
    """Baud rate the baud switches select by the manual's table (None: pattern not in the table)."""
    node_id: int | None
    node_id_source: str
    """``switches`` or the parameter the node id comes from."""
    baud_kbit: int | None
    baud_source: str
    summary: str
    rules_applied: list[str] = Field(default_factory=list)
    problems: list[str] = Field(default_factory=list)
    alternative: list[ParameterSetting] = Field(default_factory=list)
    """Parameter values that give the same node id and baud rate without switches (where possible)."""
    readback: dict[str, int] = Field(default_factory=dict)
    """Value the device's switch read-back parameter would show."""
    ambiguities: list[str] = Field(default_factory=list)


class NotSettableBySwitches(InvalidValue):
    """The node id / baud rate exists for the device but the switches cannot set it."""

    title = N_("Not settable by DIP switches")

    def __init__(self, detail: str, *, alternative: list[ParameterSetting]) -> None:
        super().__init__(detail)
        self.alternative = alternative

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "alternative": [a.model_dump() for a in self.alternative]}


def _normalise(spec: SwitchesSection, switches: dict[str, bool]) -> dict[str, bool]:
    if switches and not spec.switches:
        raise InvalidValue(_("{device} has no DIP switches; set {node} and {baud} instead.").format(
            device=spec.name, node=spec.node_parameter.code, baud=spec.baud_parameter.code))
    known = {s.label.lower(): s.label for s in spec.switches}
    result = {s.label: False for s in spec.switches}
    for label, on in switches.items():
        key = str(label).strip().lower()
        if key not in known:
            raise InvalidValue(_("{device} has no switch '{label}'. Switches: {switches}.").format(
                device=spec.name, label=label, switches=", ".join(s.label for s in spec.switches) or _("none")))
        result[known[key]] = bool(on)
    return result


def _baud_from_switches(spec: SwitchesSection, positions: dict[str, bool]) -> int | None:
    for row in spec.baud_table:
        if all(positions[label] == on for label, on in row.positions.items()):
            return row.baud_kbit
    return None


def _unlisted_baud(spec: SwitchesSection, positions: dict[str, bool]) -> str:
    labels = [s.label for s in spec.baud_switches]
    on = [label for label in labels if positions[label]]
    if len(on) == len(labels):
        where = _("{switches} all ON").format(switches=", ".join(labels))
    else:
        where = ", ".join(f"{label} {_('ON') if positions[label] else _('OFF')}" for label in labels)
    return _("Baud switches {where}: this position is not in the {table} table.").format(
        where=where, table=spec.baud_table_source)


def _check_baud(spec: SwitchesSection, baud_kbit: int) -> None:
    if baud_kbit not in spec.baud_rates_kbit:
        raise InvalidValue(_("{device} does not support {baud} kbit/s. Baud rates: {rates} kbit/s.").format(
            device=spec.name, baud=baud_kbit, rates=", ".join(str(b) for b in spec.baud_rates_kbit)))


def code_alternative(spec: SwitchesSection, node_id: int, baud_kbit: int) -> list[ParameterSetting]:
    """Parameter values that set ``node_id`` and ``baud_kbit`` without switches (a note says where impossible)."""
    lo, hi = spec.node_parameter.range
    settings = []
    for setting in spec.settings:
        value: int | None
        if setting.sets == "node_id":
            possible, value = lo <= node_id <= hi, node_id
        elif setting.values:
            possible, value = baud_kbit in setting.values, setting.values.get(baud_kbit)
        else:
            possible, value = baud_kbit in spec.baud_parameter.rates_kbit, baud_kbit
        value = value if possible else None
        note = setting.note if possible or setting.unavailable is None else setting.unavailable
        fields = {"node_id": node_id, "baud_kbit": baud_kbit, "value": value}
        settings.append(ParameterSetting(code=setting.code, value=value, meaning=setting.meaning.format(**fields),
                                         note=None if note is None else note.format(**fields)))
    return settings


def _readback(spec: SwitchesSection, positions: dict[str, bool]) -> dict[str, int]:
    if spec.readback is None:
        return {}
    value = sum(1 << (s.readback_bit or 0) for s in spec.switches if positions[s.label])
    for bit in spec.readback.set_bits:
        value |= 1 << bit
    return {spec.readback.code: value}


def decode(device: SwitchDevice, switches: dict[str, bool], *, code_node_id: int | None = None,
           code_baud_kbit: int | None = None) -> DipResult:
    """What the device uses with these switch positions.

    ``code_node_id``/``code_baud_kbit`` are the values in the node-address/baud-rate parameters; their factory
    values are assumed where the section gives them."""
    spec = device.spec
    positions = _normalise(spec, switches)
    total = sum(s.weight or 0 for s in spec.address_switches if positions[s.label])
    baud_switch = _baud_from_switches(spec, positions) if spec.baud_switches else None
    cases: list[Case] = []
    notes: list[str] = []
    problems: list[str] = []
    node = spec.node_parameter
    node_id: int | None
    if total == 0:
        node_id, node_source = (node.default if code_node_id is None else code_node_id), node.code
        cases.append("node_from_parameter")
        if code_node_id is None and node.default_note:
            notes.append(node.default_note)
        lo, hi = node.range
        if node_id is not None and not lo <= node_id <= hi:
            problems.append(node.invalid.format(code=node.code, value=node_id, lo=lo, hi=hi))
    else:
        node_id, node_source = total, "switches"
        lo, hi = spec.switch_node_range or (1, 127)
        if total > hi and spec.above_range_node_id is not None:
            node_id = spec.above_range_node_id
            cases.append("node_above_range")
        else:
            cases.append("node_from_switches")
            if total > hi:
                problems.append(_("The address switches give {total}, outside {lo} … {hi}.").format(
                    total=total, lo=lo, hi=hi))
    baud = spec.baud_parameter
    all_baud_off = not any(positions[s.label] for s in spec.baud_switches)
    from_parameter = (not spec.baud_switches or (total == 0 and spec.all_address_off == "node_and_baud_from_parameters")
                      or (all_baud_off and spec.all_baud_off == "baud_from_parameter"))
    baud_kbit: int | None
    if from_parameter:
        baud_kbit, baud_source = (baud.default_kbit if code_baud_kbit is None else code_baud_kbit), baud.code
        cases.append("baud_from_parameter")
        if baud_kbit is not None and baud_kbit not in baud.rates_kbit:
            problems.append(baud.invalid.format(code=baud.code, value=baud_kbit))
    else:
        baud_kbit, baud_source = baud_switch, "switches"
        cases.append("baud_from_switches")
        if baud_switch is None:
            problems.append(_unlisted_baud(spec, positions))
    rules = [rule.text for rule in spec.rules if cases[0] in rule.when] + notes
    rules += [rule.text for rule in spec.rules if cases[1] in rule.when and rule.text not in rules]
    node_text = _("unknown (value of the parameter not given)") if node_id is None else str(node_id)
    baud_text = _("unknown") if baud_kbit is None else f"{baud_kbit} kbit/s"
    alternative = (code_alternative(spec, node_id, baud_kbit)
                   if node_id is not None and baud_kbit is not None and baud_kbit in spec.baud_rates_kbit else [])
    return DipResult(
        family=spec.key, switches=positions, address_switch_sum=total, baud_switch_kbit=baud_switch,
        node_id=node_id, node_id_source=node_source, baud_kbit=baud_kbit, baud_source=baud_source,
        summary=_("Node id {node} (from {node_source}), baud rate {baud} (from {baud_source}).").format(
            node=node_text, node_source=_source(node_source), baud=baud_text, baud_source=_source(baud_source)),
        rules_applied=rules, problems=problems, alternative=alternative, readback=_readback(spec, positions),
        ambiguities=list(spec.ambiguities),
    )


def encode(device: SwitchDevice, node_id: int, baud_kbit: int) -> DipResult:
    """Switch positions for ``node_id`` at ``baud_kbit`` (no switches: parameter values), checked by decoding.

    Raises OutOfRange for a node id the device cannot use at all, NotSettableBySwitches (with the parameter
    alternative) for one only its parameters can set, InvalidValue for an unsupported baud rate.
    """
    spec = device.spec
    _check_baud(spec, baud_kbit)
    if not spec.address_switches:
        lo, hi = spec.node_parameter.range
        if not lo <= node_id <= hi:
            raise OutOfRange(_outside(spec.name, node_id, lo, hi))
        return decode(device, {}, code_node_id=node_id, code_baud_kbit=baud_kbit)
    lo, hi = spec.switch_node_range or (1, 127)
    if not lo <= node_id <= hi:
        clo, chi = spec.node_parameter.range
        if clo <= node_id <= chi:
            raise NotSettableBySwitches(_("Node id {node} cannot be set by the switches of {device}.").format(
                                        node=node_id, device=spec.name),
                                        alternative=code_alternative(spec, node_id, baud_kbit))
        raise OutOfRange(_outside(spec.name, node_id, lo, hi))
    positions = {s.label: bool(node_id & (s.weight or 0)) for s in spec.address_switches}
    row = next((r for r in spec.baud_table if r.baud_kbit == baud_kbit), None)
    if row is not None:
        positions.update(row.positions)
    result = decode(device, positions, code_baud_kbit=baud_kbit)
    if (result.node_id, result.baud_kbit) != (node_id, baud_kbit):
        raise InvalidValue(_("{device}: the switches give node id {got} at {got_baud} kbit/s for {node} at {baud} "
                             "kbit/s; its switches section does not add up.").format(
                                 device=spec.name, got=result.node_id, got_baud=result.baud_kbit, node=node_id,
                                 baud=baud_kbit))
    return result


def _outside(device: str, node_id: int, lo: int, hi: int) -> str:
    return _("{device}: node id {node} is outside {lo} … {hi}.").format(device=device, node=node_id, lo=lo, hi=hi)


def _source(source: str) -> str:
    """``switches`` in words; a parameter code as it is."""
    return _("switches") if source == "switches" else source
