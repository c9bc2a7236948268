"""The plan of a recording sampled by PDO: which free TPDO of which node carries which channel, the bus share the
recording takes, and the nodes that fall back to polling (with why).

A channel is one of the node's TPDO-mappable objects (a status-word bit maps the whole word; the bit is picked in
software). Each node's objects are packed, in channel order, into as few TPDOs as 64 bits and the mapping's entry
count allow. A TPDO is free when its COB-ID is invalid (CiA 301: not used) or when it is valid with nothing mapped
(it sends nothing); its mapping must be writable and the profile's pdo_rules must accept the mapping. Every TPDO is
configured "synchronous, every SYNC" (type 1), inhibit time 0; the tool produces the SYNC.

The bus share counts the exact bits of every frame per SYNC period (:func:`drivebench.transport.busload.frame_bits`,
the count the monitor uses): the SYNC frame and each TPDO with its identifier and length, data all zero (a drive at
rest; zeros also give the most stuff bits).
"""

from __future__ import annotations

from dataclasses import dataclass

from drivebench.device.profiles import pdo_notes
from drivebench.device.profiles.catalog import Catalog
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.protocol.canopen.network import frames_of
from drivebench.services.bus.sessions import Session
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import MAX_PDO_BITS, MappedObject, PdoConfig
from drivebench.services.scope.source import ScopeChannel
from drivebench.transport.busload import frame_bits

SYNC_COB_ID = 0x080
SYNC_EVERY = 1
"""Transmission type of a recording's TPDOs: synchronous, every SYNC."""
MAX_BUS_SHARE = 80.0
MIN_PERIOD_S = 0.001


@dataclass(frozen=True)
class PlannedTpdo:
    node: int
    number: int
    cob_id: int
    entries: tuple[MappedObject, ...]

    @property
    def length(self) -> int:
        return sum(entry.bits for entry in self.entries) // 8

    @property
    def name(self) -> str:
        return f"TPDO{self.number}"


@dataclass(frozen=True)
class ChannelSlot:
    """Where a channel's value sits in a TPDO frame."""

    cob_id: int
    offset: int
    bits: int
    signed: bool
    bit: int | None = None

    def value(self, data: bytes) -> int | None:
        if (self.offset + self.bits + 7) // 8 > len(data):
            return None
        field = (int.from_bytes(data, "little") >> self.offset) & ((1 << self.bits) - 1)
        if self.bit is not None:
            return (field >> self.bit) & 1
        if self.signed and field >> (self.bits - 1):
            field -= 1 << self.bits
        return field


@dataclass(frozen=True)
class PollingNode:
    node: int
    reason: str


@dataclass(frozen=True)
class ScopePlan:
    period_s: float
    channels: tuple[ScopeChannel, ...]
    tpdos: tuple[PlannedTpdo, ...]
    slots: tuple[ChannelSlot | None, ...]
    """Per channel, in channel order; None for a channel of a node sampled by polling."""
    polling: tuple[PollingNode, ...]
    start_nodes: tuple[int, ...]
    """Nodes not known to be operational (pre-operational, no heartbeat yet): an NMT start makes them send."""
    bits_per_sync: int
    bitrate: int

    @property
    def pdo_nodes(self) -> tuple[int, ...]:
        return tuple(sorted({tpdo.node for tpdo in self.tpdos}))

    @property
    def bus_share(self) -> float:
        """Per cent of the bus the recording's frames take."""
        if not self.tpdos:
            return 0.0
        return 100.0 * self.bits_per_sync / (self.period_s * self.bitrate)

    def texts(self) -> list[str]:
        """The plan in words, for the page before it starts."""
        lines = [_("Node {node}: {pdo} (COB-ID 0x{cob}) carries {refs}, synchronous every SYNC.").format(
            node=tpdo.node, pdo=tpdo.name, cob=f"{tpdo.cob_id:03X}", refs=", ".join(e.ref for e in tpdo.entries))
            for tpdo in self.tpdos]
        lines += polling_texts(self.polling)
        if self.tpdos:
            lines.append(_("SYNC every {period} ms from DriveBench; the recording takes a bus share of {share} % "
                           "({bits} bits per SYNC at {rate} kbit/s).").format(
                period=f"{self.period_s * 1000:g}", share=f"{self.bus_share:.1f}", bits=self.bits_per_sync,
                rate=f"{self.bitrate / 1000:g}"))
        if self.start_nodes:
            lines.append(_("Nodes {nodes} are not known to be operational: the recording starts them (NMT "
                           "start).").format(nodes=", ".join(str(node) for node in self.start_nodes)))
        return lines


def _resolve(session: Session, catalog: Catalog, channel: ScopeChannel) -> MappedObject:
    try:
        item = catalog.resolve(channel.ref)
    except DriveBenchError as exc:
        raise InvalidValue(_("Channel {ref} of node {node}: {why}").format(
            ref=channel.ref, node=channel.node, why=exc.shown_detail())) from exc
    mappable = {(m.index, m.subindex): m for m in pdo.mappable_objects(session, channel.node, "tpdo")}
    found = mappable.get((item.index, item.subindex))
    if found is None:
        raise InvalidValue(_("{ref} ({name}) of node {node} cannot be sampled by PDO: the profile does not list it "
                             "as TPDO-mappable.").format(ref=item.ref, name=item.name, node=channel.node))
    if channel.bit is not None and not 0 <= channel.bit < found.bits:
        raise InvalidValue(_("{ref} has {bits} bits: there is no bit {bit}.").format(
            ref=item.ref, bits=found.bits, bit=channel.bit))
    return found


def _pack(objects: list[MappedObject], max_entries: int) -> list[list[MappedObject]]:
    """First fit, in channel order, into TPDOs of 64 bits and ``max_entries`` entries."""
    bins: list[list[MappedObject]] = []
    for obj in objects:
        for chosen in bins:
            if sum(m.bits for m in chosen) + obj.bits <= MAX_PDO_BITS and len(chosen) < max_entries:
                chosen.append(obj)
                break
        else:
            bins.append([obj])
    return bins


def _not_free(catalog: Catalog, config: PdoConfig) -> str | None:
    """Why this TPDO cannot carry a recording, in words (None: it is free)."""
    name, refs = f"TPDO{config.number}", ", ".join(entry.ref for entry in config.entries)
    if config.fixed_mapping:
        return _("{pdo} has a fixed mapping ({refs})").format(pdo=name, refs=refs or "-")
    if config.valid and config.static_mapping:
        return _("{pdo} sends the device's static mapping ({refs})").format(pdo=name, refs=refs)
    if config.valid and config.entries:
        return _("{pdo} is in use ({refs})").format(pdo=name, refs=refs)
    if not _type_allowed(catalog, config.number):
        return _("{pdo} cannot be made synchronous").format(pdo=name)
    if not config.max_entries:
        return _("{pdo} has no mapping entries").format(pdo=name)
    return None


def _type_allowed(catalog: Catalog, number: int) -> bool:
    item = catalog.by_address(pdo.COMM_BASE["tpdo"] + number - 1, 2)
    if item is None:
        return False  # no transmission type object: the TPDO cannot be made synchronous
    entry = item.entry
    if not entry.access.writable:
        return False
    return not (entry.selection and SYNC_EVERY not in entry.selection) and \
        (entry.max is None or entry.max >= SYNC_EVERY)


def _accepted(session: Session, node: int, number: int, objects: list[MappedObject]) -> list[MappedObject] | None:
    """The mapping in an order the profile accepts (the channels' own, else the device's mapping sequence from its
    pdo_rules, else by index), or None."""
    orders = [objects]
    by_key = {(m.index, m.subindex): m for m in objects}
    sequence = pdo_notes.in_mapping_sequence(pdo.node_catalog(session, node).profile, "tpdo", number, list(by_key))
    if sequence is not None:
        orders.append([by_key[key] for key in sequence])
    orders.append(sorted(objects, key=lambda m: (m.index, m.subindex)))
    for order in orders:
        try:
            return pdo.check_mapping(session, node, "tpdo", number, [(m.index, m.subindex) for m in order],
                                     name=f"TPDO{number}")
        except InvalidValue:
            continue
    return None


def _state(session: Session, node: int) -> tuple[str | None, bool]:
    """Why the node cannot send PDOs (None: it can) and whether it needs an NMT start first."""
    state, _live = session.nmt_state(node)
    if state.startswith("Operational"):
        return None, False
    if state.startswith(("Pre-operational", "Boot-up", "Unknown", "Heartbeat lost")):
        # an NMT start makes it send its TPDOs; a heartbeat that came late (a loaded host) says nothing of a node
        # that answers: the set-up's SDO writes find out whether it is there and refuse in words if it is not
        return None, True
    return _("it is not operational (NMT state: {state}), so it sends no PDOs; the recording does not start it "
             "from there.").format(state=_(state)), False


async def _plan_node(session: Session, node: int, objects: list[MappedObject]
                     ) -> tuple[list[PlannedTpdo], str | None, bool]:
    why, start = _state(session, node)
    if why:
        return [], why, False
    catalog = pdo.node_catalog(session, node)
    free: list[PdoConfig] = []
    taken: list[str] = []
    for number in pdo.pdo_numbers(session, node, "tpdo"):
        config = await pdo.read_pdo(session, node, "tpdo", number)
        why_not = _not_free(catalog, config)
        if why_not is None:
            free.append(config)
        else:
            taken.append(why_not)
    if not free:
        return [], _("it has no free TPDO: {why}.").format(why="; ".join(taken) or _("it has none")), False
    max_entries = min(config.max_entries for config in free)
    bins = _pack(objects, max_entries)
    if len(bins) > len(free):
        raise InvalidValue(_("The channels of node {node} need {needed} TPDOs ({bits} bits); it has {free} free. "
                             "Record fewer channels of node {node}.").format(
            node=node, needed=len(bins), bits=sum(m.bits for m in objects), free=len(free)))
    planned = []
    for config, chosen in zip(free, bins, strict=False):
        accepted = _accepted(session, node, config.number, chosen)
        if accepted is None:
            return [], _("its profile's PDO rules do not accept this mapping in TPDO{number}.").format(
                number=config.number), False
        planned.append(PlannedTpdo(node, config.number, config.cob_id, tuple(accepted)))
    return planned, None, start


def without_frames(channels: list[ScopeChannel]) -> tuple[PollingNode, ...]:
    """The nodes of a bus that carries no process data here (the EtherCAT unit behind the mailbox gateway)."""
    return tuple(PollingNode(node, _("EtherCAT behind a mailbox gateway carries no process data here."))
                 for node in sorted({c.node for c in channels}))


def polling_texts(polling: tuple[PollingNode, ...]) -> list[str]:
    return [_("Node {node} is sampled by polling: {reason}").format(node=poll.node, reason=poll.reason)
            for poll in polling]


async def plan_recording(session: Session, channels: list[ScopeChannel], period_s: float) -> ScopePlan:
    """The plan for ``channels`` at a SYNC period of ``period_s``; InvalidValue in words for what cannot be."""
    if not channels:
        raise InvalidValue(_("A recording needs at least one channel."))
    if period_s < MIN_PERIOD_S - 1e-12:
        raise InvalidValue(_("The SYNC period must be at least 1 ms."))
    if not session.network.capabilities.frames:
        return ScopePlan(period_s, tuple(channels), (), (None,) * len(channels), without_frames(channels), (), 0, 1)
    by_node: dict[int, list[MappedObject]] = {}
    resolved = []
    for channel in channels:
        obj = _resolve(session, pdo.node_catalog(session, channel.node), channel)
        resolved.append(obj)
        objects = by_node.setdefault(channel.node, [])
        if all((m.index, m.subindex) != (obj.index, obj.subindex) for m in objects):
            objects.append(obj)
    tpdos: list[PlannedTpdo] = []
    polling: list[PollingNode] = []
    start: list[int] = []
    for node, objects in by_node.items():
        planned, why, needs_start = await _plan_node(session, node, objects)
        tpdos += planned
        if why:
            polling.append(PollingNode(node, why))
        if needs_start:
            start.append(node)
    slots = tuple(_slot(session, tpdos, channel, obj) for channel, obj in zip(channels, resolved, strict=True))
    bitrate = frames_of(session.network).spec.bitrate
    bits = frame_bits(SYNC_COB_ID) + sum(frame_bits(t.cob_id, bytes(t.length)) for t in tpdos)
    plan = ScopePlan(period_s, tuple(channels), tuple(tpdos), slots, tuple(polling), tuple(sorted(start)), bits,
                     bitrate)
    if plan.bus_share > MAX_BUS_SHARE:
        shortest = bits / (MAX_BUS_SHARE / 100 * bitrate)
        raise InvalidValue(_("At {period} ms the recording would take a bus share of {share} % ({bits} bits per SYNC "
                             "at {rate} kbit/s); {limit} % at most is allowed. Choose a period of {shortest} ms or "
                             "more, or fewer channels.").format(
            period=f"{period_s * 1000:g}", share=f"{plan.bus_share:.0f}", bits=bits, rate=f"{bitrate / 1000:g}",
            limit=f"{MAX_BUS_SHARE:g}", shortest=f"{shortest * 1000:.2f}"))
    return plan


def _slot(session: Session, tpdos: list[PlannedTpdo], channel: ScopeChannel, obj: MappedObject
          ) -> ChannelSlot | None:
    for tpdo in tpdos:
        if tpdo.node != channel.node:
            continue
        offset = 0
        for entry in tpdo.entries:
            if (entry.index, entry.subindex) == (obj.index, obj.subindex):
                return ChannelSlot(tpdo.cob_id, offset, entry.bits, _signed(session, tpdo.node, entry), channel.bit)
            offset += entry.bits
    return None


def _signed(session: Session, node: int, obj: MappedObject) -> bool:
    item = pdo.node_catalog(session, node).by_address(obj.index, obj.subindex)
    return item is not None and item.entry.data_type.is_signed
