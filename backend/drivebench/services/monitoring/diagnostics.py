"""Node health: EMCY history decoded with the manual's texts, heartbeat producer/consumers, boot-ups.

Everything shown to viewers comes from what the heartbeat and EMCY consumers already hold; only the heartbeat
set-up reads and writes the device (through the node's SDO lock), so any number of viewers cost the bus nothing.
"""

from __future__ import annotations

import time

from pydantic import BaseModel

from drivebench.device.drive.faults import DecodedFault, decode_emcy
from drivebench.device.profiles.profile import EmcyCode, Profile
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import N_, _
from drivebench.protocol.canopen.guarding import GuardStatus
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.emcy import EmcyEvent
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import lookup, node_lease, reads, writes
from drivebench.services.params.write_context import WriteContext

HEARTBEAT_PRODUCER = 0x1017
HEARTBEAT_CONSUMERS = 0x1016
GUARD_TIME = 0x100C
LIFE_TIME_FACTOR = 0x100D
# The words a node's NMT state is given in (heartbeat, guarding, boot-up, the bus): shown in the reader's language
NMT_WORDS = frozenset({N_("Boot-up"), N_("Stopped"), N_("Operational"), N_("Pre-operational"), N_("Unknown"),
                       N_("Adapter lost"), N_("Bus-off"), N_("Node guarding lost"), N_("Heartbeat lost")})
COMMANDED = " (commanded)"


def nmt_state_text(state: str) -> str:
    """``Pre-operational (commanded)`` as the reader's language says it; any other word (an EtherCAT AL status as
    the master reports it) as it is."""
    if state.endswith(COMMANDED) and state.removesuffix(COMMANDED) in NMT_WORDS:
        return _("{state} (commanded)").format(state=_(state.removesuffix(COMMANDED)))
    return _(state) if state in NMT_WORDS else state


class EmcyRecord(BaseModel):
    node_id: int
    time: float
    code: str
    error_register: str
    register_bits: list[str]
    class_text: str
    vendor_error: str | None
    vendor_text: str | None
    remedy: str | None
    data: str
    is_reset: bool
    fault: DecodedFault | None = None
    """The device's own fault number in the telegram, in the manual's words (its profile's ``faults``)."""

    @property
    def text(self) -> str:
        if self.is_reset:
            return _("Error reset / no error")
        return self.vendor_text or self.class_text


class HeartbeatConsumer(BaseModel):
    slot: int
    producer_id: int
    time_ms: int

    @property
    def active(self) -> bool:
        return self.producer_id != 0 and self.time_ms != 0


class HeartbeatSetup(BaseModel):
    node_id: int
    producer_time_ms: int
    consumers: list[HeartbeatConsumer]


class GuardingPublic(BaseModel):
    guard_time_ms: int
    life_time_factor: int
    lost: bool
    state: str | None
    requests: int
    answers: int
    toggle_errors: int
    last_answer: float | None


class NodeHealth(BaseModel):
    node_id: int
    device: str
    nmt_state: str
    nmt_state_text: str
    """``nmt_state`` in the reader's language (``nmt_state`` itself names the state's style)."""
    heartbeat_age_s: float | None
    heartbeat_period_ms: float | None
    heartbeat_lost: bool
    bootups: int
    last_bootup: float | None
    active_emcy: EmcyRecord | None
    emcy_count: int
    guarding: GuardingPublic | None = None


def vendor_emcy(profile: Profile | None, code: int) -> EmcyCode | None:
    if profile is None:
        return None
    return next((entry for entry in profile.emcy_codes if entry.code == code), None)


def emcy_record(event: EmcyEvent, profile: Profile | None) -> EmcyRecord:
    vendor = vendor_emcy(profile, event.code)
    return EmcyRecord(
        node_id=event.node_id, time=event.timestamp, code=f"0x{event.code:04X}",
        error_register=f"0x{event.register:02X}", register_bits=event.register_bits, class_text=event.class_text,
        vendor_error=vendor.vendor_error if vendor else None, vendor_text=vendor.text if vendor else None,
        remedy=vendor.remedy if vendor else None, data=event.data.hex(" ").upper(), is_reset=event.is_reset,
        fault=decode_emcy(profile.faults if profile else None, event.code, event.data))


def emcy_history(session: Session, node_id: int) -> list[EmcyRecord]:
    """The node's emergencies, newest first."""
    profile = session.nodes[node_id].profile if node_id in session.nodes else None
    return [emcy_record(event, profile) for event in reversed(session.network.emcy.history(node_id))]


def node_health(session: Session, node: SessionNode, now: float | None = None) -> NodeHealth:
    now = now or time.time()
    status = session.heartbeat(node.node_id)
    period = status.expected_period_s()
    active = session.network.emcy.active(node.node_id)
    guard = session.guarding.status(node.node_id) if session.guarding is not None else None
    state = session.nmt_state(node.node_id)[0]
    return NodeHealth(
        node_id=node.node_id, device=node.device_name, nmt_state=state, nmt_state_text=nmt_state_text(state),
        heartbeat_age_s=status.age_s(now), heartbeat_period_ms=round(period * 1000, 1) if period else None,
        heartbeat_lost=guard is None and status.is_lost(now), bootups=status.bootups, last_bootup=status.last_bootup,
        active_emcy=emcy_record(active, node.profile) if active else None,
        emcy_count=len(session.network.emcy.history(node.node_id)),
        guarding=guarding_public(guard, now) if guard else None)


def guarding_public(guard: GuardStatus, now: float | None = None) -> GuardingPublic:
    return GuardingPublic(guard_time_ms=round(guard.guard_time_s * 1000), life_time_factor=guard.life_time_factor,
                          lost=guard.is_lost(now), state=_(guard.state.label) if guard.state else None,
                          requests=guard.requests, answers=guard.answers, toggle_errors=guard.toggle_errors,
                          last_answer=guard.last_answer)


def network_health(session: Session) -> list[NodeHealth]:
    now = time.time()
    return [node_health(session, node, now) for node in sorted(session.nodes.values(), key=lambda n: n.node_id)]


AUDIT_ORIGIN = "diagnostics"


async def _send(session: Session, node_id: int, index: int, subindex: int, data: bytes, ctx: WriteContext) -> None:
    """A write of the Diagnostics tab (heartbeat, node guarding), read back, in the audit log as ``ctx``'s with the
    origin ``diagnostics``."""
    await writes.send_logged(session, node_id, index, subindex, data, ctx=ctx.as_origin(AUDIT_ORIGIN), verify=True)


# --- heartbeat set-up (8400 motec manual's commissioning example: consumer = producer id + time) ----------------
def _u(data: bytes) -> int:
    return int.from_bytes(data, "little")


async def read_heartbeat_setup(session: Session, node_id: int) -> HeartbeatSetup:
    client = session.client(node_id)
    producer = _u(await client.aupload(HEARTBEAT_PRODUCER, 0))
    consumers: list[HeartbeatConsumer] = []
    count = _u(await client.aupload(HEARTBEAT_CONSUMERS, 0))
    for slot in range(1, count + 1):
        entry = _u(await client.aupload(HEARTBEAT_CONSUMERS, slot))
        consumers.append(HeartbeatConsumer(slot=slot, producer_id=(entry >> 16) & 0x7F, time_ms=entry & 0xFFFF))
    return HeartbeatSetup(node_id=node_id, producer_time_ms=producer, consumers=consumers)


def _configured(session: Session, node_id: int, period_ms: int) -> None:
    """The producer time the node was given, for the heartbeat consumer's loss judgement (none on EtherCAT)."""
    if session.heartbeats is not None:
        session.heartbeats.set_configured_period(node_id, period_ms)


@node_lease.leased
async def write_heartbeat_producer(session: Session, node_id: int, ctx: WriteContext, time_ms: int) -> HeartbeatSetup:
    if not 0 <= time_ms <= 0xFFFF:
        raise InvalidValue(_("Heartbeat producer time {time} ms is outside 0 … 65535 ms (0 = off).").format(
            time=time_ms))
    await _send(session, node_id, HEARTBEAT_PRODUCER, 0, time_ms.to_bytes(2, "little"), ctx)
    _configured(session, node_id, time_ms)
    setup = await read_heartbeat_setup(session, node_id)
    if setup.producer_time_ms != time_ms:
        raise InvalidValue(_("Node {node} reads back a heartbeat producer time of {read} ms after {time} ms was "
                             "written.").format(node=node_id, read=setup.producer_time_ms, time=time_ms))
    return setup


@node_lease.leased
async def _producer_period_s(session: Session, producer_id: int, ctx: WriteContext) -> float | None:
    """The producer's configured heartbeat time (its 0x1017, what CiA 301 compares a consumer time with); the period
    measured from its telegrams only when the producer cannot be asked (a late telegram must not refuse a right
    consumer time)."""
    status = session.heartbeat(producer_id)
    if status.configured_period_s is not None:
        return status.configured_period_s
    try:
        configured = _u(await session.client(producer_id).aupload(HEARTBEAT_PRODUCER, 0))
    except DriveBenchError:
        return status.period_s
    _configured(session, producer_id, configured)
    return configured / 1000 if configured else None


async def write_heartbeat_consumer(session: Session, node_id: int, ctx: WriteContext, slot: int, producer_id: int,
                                   time_ms: int) -> HeartbeatSetup:
    """CiA 301 0x1016: bits 16..22 producer node id, bits 0..15 consumer time in ms (0 = slot unused)."""
    if not 0 <= producer_id <= 127:
        raise InvalidValue(_("Producer node id {producer} is not a CANopen node id (1 … 127, 0 = unused).").format(
            producer=producer_id))
    if not 0 <= time_ms <= 0xFFFF:
        raise InvalidValue(_("Consumer time {time} ms is outside 0 … 65535 ms.").format(time=time_ms))
    if producer_id == node_id and time_ms:
        raise InvalidValue(_("Node {node} cannot consume its own heartbeat.").format(node=node_id))
    setup = await read_heartbeat_setup(session, node_id)
    if not 1 <= slot <= len(setup.consumers):
        raise InvalidValue(_("Node {node} has {count} heartbeat consumer entries; entry {slot} does not exist.")
                           .format(node=node_id, count=len(setup.consumers), slot=slot))
    producer = await _producer_period_s(session, producer_id, ctx) if producer_id and time_ms else None
    if producer and time_ms and time_ms <= producer * 1000:
        raise InvalidValue(_("Consumer time {time} ms must be longer than node {producer}'s heartbeat producer time "
                             "({period} ms), or every heartbeat would be late.").format(
            time=time_ms, producer=producer_id, period=f"{producer * 1000:.0f}"))
    entry = (producer_id << 16) | time_ms
    await _send(session, node_id, HEARTBEAT_CONSUMERS, slot, entry.to_bytes(4, "little"), ctx)
    setup = await read_heartbeat_setup(session, node_id)
    written = setup.consumers[slot - 1]
    if (written.producer_id, written.time_ms) != (producer_id, time_ms):
        raise InvalidValue(_("Node {node} reads back consumer entry {slot} as node {read_producer}, {read_time} ms "
                             "after node {producer}, {time} ms was written.").format(
            node=node_id, slot=slot, read_producer=written.producer_id, read_time=written.time_ms,
            producer=producer_id, time=time_ms))
    return setup


# --- node guarding (devices that use it instead of heartbeat: EMF2178IB, MICROMASTER) ---------------------------
@node_lease.leased
async def start_guarding(session: Session, node_id: int, ctx: WriteContext, guard_time_ms: int,
                         life_time_factor: int) -> GuardingPublic:
    """Write guard time (0x100C) and life time factor (0x100D) to the node, then guard it; 0 ms stops guarding."""
    node = session.node(node_id)
    if node.profile is not None and not node.profile.features.node_guarding:
        raise InvalidValue(_("{device} (node {node}) does not support node guarding per its profile; use the "
                             "heartbeat instead.").format(device=node.device_name, node=node_id))
    if not 0 <= guard_time_ms <= 0xFFFF or not 0 <= life_time_factor <= 0xFF:
        raise InvalidValue(_("Guard time must be 0 … 65535 ms and life time factor 0 … 255."))
    if guard_time_ms and life_time_factor:  # CiA 301: a node with a heartbeat producer time does not guard
        await _send(session, node_id, HEARTBEAT_PRODUCER, 0, (0).to_bytes(2, "little"), ctx)
        _configured(session, node_id, 0)
    await _send(session, node_id, GUARD_TIME, 0, guard_time_ms.to_bytes(2, "little"), ctx)
    await _send(session, node_id, LIFE_TIME_FACTOR, 0, life_time_factor.to_bytes(1, "little"), ctx)
    if guard_time_ms == 0 or life_time_factor == 0:
        if session.guarding is not None:
            session.guarding.release(node_id)
        return GuardingPublic(guard_time_ms=0, life_time_factor=life_time_factor, lost=False, state=None,
                              requests=0, answers=0, toggle_errors=0, last_answer=None)
    return guarding_public(frames_of(session.network).guarding.start(node_id, guard_time_ms, life_time_factor))


# --- vendor diagnostic parameters (8400 motec bus status C00359 and telegram counters, MICROMASTER r2054 ...) -----
class DiagnosticValue(BaseModel):
    ref: str
    name: str
    group: str
    display: str | None
    unit: str | None
    error: str | None


def diagnostic_groups(node: SessionNode) -> list[str]:
    """The profile's diagnostics groups, in the manual's order."""
    if node.profile is None:
        return []
    return [g for g in node.profile.groups if "diagnos" in g.lower()]


async def read_diagnostics(session: Session, node_id: int) -> list[DiagnosticValue]:
    """Read every readable parameter of the node's diagnostics groups; one failing value does not stop the rest."""
    node = session.node(node_id)
    wanted = diagnostic_groups(node)
    values: list[DiagnosticValue] = []
    for group in wanted:
        for item in lookup.readable_items(node, group):
            try:
                value = await reads.read(session, node_id, item.ref)
                values.append(DiagnosticValue(ref=item.ref, name=item.name, group=group, display=value.display,
                                              unit=value.unit, error=None))
            except DriveBenchError as exc:
                values.append(DiagnosticValue(ref=item.ref, name=item.name, group=group, display=None,
                                              unit=item.entry.unit, error=exc.shown_detail()))
    return values
