"""The channels a recording may take and what each one is: its name, unit and scaling from the node's profile.

Offered are the node's PDO-mappable objects (what sampling by PDO can carry) and the actual values of the profile's
control section (8400: the speed in CAN1_OUT word 2, scaled 0x4000 = C00011); a recording may name any readable
object of the node (polling reads it by SDO). A word the control section scales (``full_scale_raw`` of a reference
parameter, ``raw_per_unit``) is shown in that unit; every other value with the entry's own factor and unit; a bit
of a word is 0 or 1.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivebench.device.drive.control import WordScale
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control.drive_words import family_of
from drivebench.services.params import reads
from drivebench.services.params.lookup import resolve
from drivebench.services.pdos.pdo import mappable_objects
from drivebench.services.scope.source import ScopeChannel

MAX_CHANNELS = 8


@dataclass(frozen=True)
class ChannelInfo:
    """A channel as the recording shows and scales it."""

    channel: ScopeChannel
    name: str
    unit: str | None
    raw_per_unit: float | None
    """A process-data word the control section scales (signed 16 bits / this); None: the entry's factor."""
    item: Item

    @property
    def label(self) -> str:
        bit = f" bit {self.channel.bit}" if self.channel.bit is not None else ""
        return f"{self.channel.node}: {self.channel.ref}{bit} {self.name}"

    def value(self, raw: int | None) -> float | None:
        if raw is None:
            return None
        if self.channel.bit is not None:
            return float(raw >> self.channel.bit & 1)
        if self.raw_per_unit:
            signed = raw - 0x10000 if 0x8000 <= raw <= 0xFFFF else raw
            return round(signed / self.raw_per_unit, 3)
        value = from_raw(self.item.entry, raw).value
        return float(value) if isinstance(value, (int, float)) else None

    def as_json(self) -> dict[str, object]:
        return {"node": self.channel.node, "ref": self.channel.ref, "bit": self.channel.bit, "name": self.name,
                "unit": self.unit, "label": self.label}


@dataclass(frozen=True)
class Candidate:
    node: int
    ref: str
    name: str
    unit: str | None
    index: int
    subindex: int
    bits: int


def _word_scales(node: SessionNode) -> dict[str, tuple[WordScale, str | None]]:
    family = family_of(node.catalog)
    if family is None:
        return {}
    found: dict[str, tuple[WordScale, str | None]] = {}
    for spec in family.section.actual_values:
        if spec.scale is not None:
            found[spec.ref] = (spec.scale, spec.unit)
    for setpoint in family.section.setpoints:
        if setpoint.scale is not None and setpoint.unit not in ("position", "velocity"):
            found.setdefault(setpoint.ref, (setpoint.scale, setpoint.unit))
    return found


def candidates(session: Session, node_id: int, query: str = "") -> list[Candidate]:
    """What the channel picker offers for a node: the profile's TPDO-mappable objects and the control section's
    actual values, filtered by ``query`` (a part of the name, the code or the index, any case)."""
    node = session.node(node_id)
    found: dict[tuple[int, int], Candidate] = {}
    if node.catalog is not None:
        scaled = _word_scales(node)
        family = family_of(node.catalog)
        for spec in family.section.actual_values if family is not None else []:
            try:
                item = node.catalog.resolve(spec.ref)
            except DriveBenchError:
                continue
            unit = scaled[spec.ref][1] if spec.ref in scaled else item.entry.unit
            bits = (item.entry.data_type.size or 0) * 8
            found[(item.index, item.subindex)] = Candidate(node_id, item.ref, f"{_(spec.label)} ({item.name})", unit,
                                                           item.index, item.subindex, bits)
        for mapped in mappable_objects(session, node_id, "tpdo"):
            key = (mapped.index, mapped.subindex)
            if key not in found:
                found[key] = Candidate(node_id, mapped.ref, mapped.name, mapped.unit, mapped.index, mapped.subindex,
                                       mapped.bits)
    wanted = query.strip().lower()
    return [c for c in found.values()
            if not wanted or wanted in c.name.lower() or wanted in c.ref.lower() or wanted in f"0x{c.index:04x}"]


async def describe(session: Session, channels: list[ScopeChannel]) -> list[ChannelInfo]:
    """Each channel resolved on its node, scaled as its profile says; a bad one refused in words."""
    if not 1 <= len(channels) <= MAX_CHANNELS:
        raise InvalidValue(_("A recording takes 1 to {most} channels, not {count}.").format(
            most=MAX_CHANNELS, count=len(channels)))
    if len(set(channels)) != len(channels):
        raise InvalidValue(_("A channel is named twice: each channel is recorded once."))
    described = []
    for channel in channels:
        node = session.node(channel.node)
        item = resolve(node, channel.ref)
        entry = item.entry
        if not recordable(item):
            raise InvalidValue(_("Node {node}: {ref} ({name}) is not a readable number and cannot be recorded.")
                               .format(node=channel.node, ref=channel.ref, name=entry.name))
        bits = (entry.data_type.size or 0) * 8
        if channel.bit is not None and not 0 <= channel.bit < bits:
            raise InvalidValue(_("Node {node}: {ref} has bits 0 to {last}, not bit {bit}.").format(
                node=channel.node, ref=channel.ref, last=bits - 1, bit=channel.bit))
        raw_per_unit, unit = None, entry.unit
        scale = _word_scales(node).get(item.ref) or _word_scales(node).get(channel.ref)
        if scale is not None and channel.bit is None:
            raw_per_unit, unit = await _raw_per_unit(session, node, scale[0]), scale[1] or unit
        name = entry.name if channel.bit is None else _bit_name(item, channel.bit)
        described.append(ChannelInfo(channel, name, None if channel.bit is not None else unit, raw_per_unit, item))
    return described


def recordable(item: Item) -> bool:
    """A readable integer: what a recording can take (sampling by PDO or polling)."""
    entry = item.entry
    return bool(entry.access.readable and entry.data_type.is_integer and entry.data_type.size is not None)


def _bit_name(item: Item, bit: int) -> str:
    named = item.entry.bits.get(bit) if item.entry.bits else None
    return f"{item.entry.name}: {named}" if named else f"{item.entry.name} bit {bit}"


async def _raw_per_unit(session: Session, node: SessionNode, scale: WordScale) -> float | None:
    if scale.raw_per_unit:
        return scale.raw_per_unit
    reference = scale.reference_default
    if scale.reference_ref is not None:
        try:
            value = (await reads.read(session, node.node_id, scale.reference_ref)).value
            reference = float(value) if isinstance(value, (int, float)) and value else reference
        except DriveBenchError:
            pass
    return (scale.full_scale_raw or 1) / reference if reference else None


PANEL_CHANNELS = 4
PDO_BITS = 64


def panel_channels(session: Session, node_id: int, most: int = PANEL_CHANNELS) -> list[Candidate]:
    """The channels of the Control tab's compact scope panel: the status word (its changes mark the drive's states)
    and, in the order the profile's control section lists them, the actual values that fit beside it into one
    TPDO's 64 bits (so the node needs one free TPDO to be sampled by PDO); at most ``most``, each one a recording
    can take (a REAL actual value is left out). Empty for a node without a control section or CiA 402 words."""
    node = session.node(node_id)
    family = family_of(node.catalog)
    if node.catalog is None or family is None:
        return []
    offered = {(c.index, c.subindex): c for c in candidates(session, node_id)}

    def candidate(ref: str) -> Candidate | None:
        try:
            item = node.catalog.resolve(ref)  # type: ignore[union-attr]
        except DriveBenchError:
            return None
        if not recordable(item):
            return None
        return offered.get((item.index, item.subindex)) or Candidate(
            node_id, item.ref, item.name, None, item.index, item.subindex, (item.entry.data_type.size or 0) * 8)

    status = candidate(family.status_ref)
    chosen: list[Candidate] = []
    room = PDO_BITS - (status.bits if status else 0)
    for spec in family.section.actual_values:
        found = candidate(spec.ref)
        if found is None or found == status or found in chosen or found.bits > room or len(chosen) >= most - 1:
            continue
        chosen.append(found)
        room -= found.bits
    return [*chosen, *([status] if status else [])]
