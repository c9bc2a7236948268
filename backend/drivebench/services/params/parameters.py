"""Read and write a node's parameters the way a drive engineer works.

* Values come back scaled, with unit, selection text or named bits (``C00088`` raw 1020 -> 10.20 A).
* A write is validated against the profile before anything is sent (type width, range, selection list,
  read-only), then read back and compared (verify).
* Values that take effect only after reset node are flagged on the node until it boots again.
* Device commands: save, restore defaults, reset node, the way the device's profile offers them; a command whose
  write can move the drive needs the confirmation like any write (:mod:`drivebench.device.drive.motion`).
* Read-all spreads one node's reads over its SDO channels (SDO2 where the device has one) and runs different
  nodes in parallel; a read that timed out is asked again at the end, a node judged silent from evidence
  (:mod:`drivebench.services.params.node_silence`) is given up and never holds the others up.

Bus work runs in this module's own thread pool, so a slow node never waits for a free worker thread; the
transfers of a stop (:func:`stop_first`) have a pool of their own and go before every read waiting for the node.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import re
import time
import weakref
from collections import deque
from collections.abc import Awaitable, Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextvars import ContextVar
from dataclasses import dataclass, field
from enum import StrEnum
from functools import partial
from typing import Protocol, TypeVar

from drivebench.device.drive.motion import judge
from drivebench.device.profiles.addressing import IndexRef, parse_ref
from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.commands import CIA301_RESTORE, CIA301_SAVE, CommandWrite
from drivebench.device.profiles.number_base import hex_word, shows_hex
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.device.profiles.scaling import RawValue, ScaledValue, from_raw, to_raw
from drivebench.errors import (
    Conflict,
    DriveBenchError,
    InvalidValue,
    OutOfRange,
    ProtocolError,
    SdoAbortError,
    SdoOutOfStepError,
    SdoStalledError,
    SdoTimeoutError,
    TransportError,
    UnknownParameter,
    WriteOutcomeUnknown,
)
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.heartbeat import HeartbeatStatus
from drivebench.protocol.canopen.network import NodeClient, SdoChannel
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.protocol.canopen.sdo_fast import ExpeditedRequest, upload_batch, upload_expedited
from drivebench.protocol.datatypes import DataType, decode, encode
from drivebench.services.bus.fieldbus import SdoClient
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import node_lease
from drivebench.services.params.jobs import Job, JobIssue, JobManager, said
from drivebench.services.params.node_silence import NodeSilence
from drivebench.services.params.write_context import READ_ALL_ORIGIN, WriteContext

T = TypeVar("T")

_BUS_WORK = ThreadPoolExecutor(max_workers=128, thread_name_prefix="sdo")
_STOP_WORK = ThreadPoolExecutor(max_workers=8, thread_name_prefix="sdo-stop")
"""A stop's transfers never queue behind reads for a worker thread."""
_urgent: ContextVar[bool] = ContextVar("drivebench_sdo_urgent", default=False)


@dataclass
class SdoSettings:
    """Per-session SDO behaviour (the REST API and the node page can change it)."""

    timeout_s: float = 0.5
    retries: int = 1
    use_sdo2: bool = True
    """Activate and use a device's second SDO channel for read-all (where its profile has ``sdo_channels``)."""


@dataclass(slots=True)
class ParameterValue:
    """One value as read (not frozen: a frozen dataclass costs 3 us to build, a tenth of a read's own work)."""

    ref: str
    name: str
    index: int
    subindex: int
    raw: RawValue
    value: int | float | str | None
    unit: str | None
    text: str | None
    display: str
    read_at: float


@dataclass(frozen=True)
class WriteResult:
    ref: str
    written: ScaledValue
    read_back: ParameterValue | None
    verified: bool | None
    """True: the device reports what was written; False: it differs (see ``mismatch``); None: not read back."""
    mismatch: str | None
    reset_required: bool


class DeviceCommand(StrEnum):
    SAVE = "save"
    RESTORE_DEFAULTS = "restore-defaults"
    RESET_NODE = "reset-node"


@dataclass(frozen=True)
class CommandResult:
    command: DeviceCommand
    via: str
    """What was sent: ``C00002/11 = 1``, ``0x1010.1 = 'save'``, ``NMT reset node``."""
    detail: str


@dataclass
class _NodeChannels:
    sdo2: SdoChannel | None = None
    active: bool = False
    note: str | None = None


@dataclass
class SessionParameters:
    """What the parameter service keeps per session: settings, last values read, SDO2 state."""

    session_ref: weakref.ref[Session]
    settings: SdoSettings
    moving_writes: MovingWrites
    """The drive guard's checks on a write that can move the drive (given when the session opens)."""
    write_audits: WriteAudits
    """Told about every write the session sends (the server's audit log)."""
    values: dict[int, dict[str, ParameterValue]] = field(default_factory=dict)
    failures: dict[int, dict[str, str]] = field(default_factory=dict)
    """node -> ref -> why the last read job could not read it (an abort, a timeout, the node silent); a value read
    later clears it."""
    channels: dict[int, _NodeChannels] = field(default_factory=dict)

    @property
    def session(self) -> Session:
        session = self.session_ref()
        if session is None:
            raise Conflict(_("The session has been closed"))
        return session

    def remember(self, node_id: int, value: ParameterValue) -> None:
        self.values.setdefault(node_id, {})[value.ref] = value
        self.failures.get(node_id, {}).pop(value.ref, None)

    def not_read(self, node_id: int, ref: str, why: str) -> None:
        self.failures.setdefault(node_id, {})[ref] = why

    def on_heartbeat(self, status: HeartbeatStatus, event: str) -> None:
        """Boot-up: a reset node happened (by us or anyone), so pending resets are done and SDO2 is gone."""
        if event != "bootup":
            return
        session = self.session_ref()
        if session is None:
            return
        node = session.nodes.get(status.node_id)
        if node is not None:
            node.pending_reset.clear()
        state = self.channels.get(status.node_id)
        if state is not None and state.active:
            state.active = False
            client = session.network.nodes.get(status.node_id)
            if isinstance(client, NodeClient) and state.sdo2 in client.channels:
                client.channels.remove(state.sdo2)


def attach(session: Session, moving_writes: MovingWrites, write_audits: WriteAudits) -> SessionParameters:
    """The parameter state of a session (made with the session's services when it opens)."""
    network = session.network
    state = SessionParameters(weakref.ref(session), SdoSettings(network.sdo_timeout_s, network.sdo_retries),
                              moving_writes, write_audits)
    if session.heartbeats is not None:  # SDO2 comes back after a boot-up (CAN)
        session.heartbeats.add_callback(state.on_heartbeat)
    return state


class ParametersPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def parameters(self) -> SessionParameters: ...


def service(session: Session) -> SessionParameters:
    services: ParametersPart = session.opened_services()
    return services.parameters


def configure(session: Session, settings: SdoSettings) -> SdoSettings:
    if not 0.01 <= settings.timeout_s <= 30 or not 0 <= settings.retries <= 10:
        raise OutOfRange(_("SDO timeout must be 0.01 ... 30 s and retries 0 ... 10"))
    state = service(session)
    state.settings = settings
    session.network.sdo_timeout_s = settings.timeout_s
    session.network.sdo_retries = settings.retries
    for client in session.network.nodes.values():
        client.configure(settings.timeout_s, settings.retries)
    return settings


async def _on_bus(work: Callable[[], T]) -> T:
    return await asyncio.get_running_loop().run_in_executor(_STOP_WORK if _urgent.get() else _BUS_WORK, work)


@contextlib.contextmanager
def stop_first(session: Session, node_id: int) -> Iterator[None]:
    """The reads and writes inside stop the drive (quick stop, disable, the guard's trip): they go before every
    transfer waiting for the node (the one on the wire finishes first), and none of those gets in between them
    (:class:`~drivebench.protocol.canopen.sdo_queue.ChannelLock`)."""
    token = _urgent.set(True)
    try:
        with session.client(node_id).stop_first():
            yield
    finally:
        _urgent.reset(token)


# --- lookup ----------------------------------------------------------------------------------------------
def _catalog(node: SessionNode) -> Catalog | None:
    return node.catalog


_BRACKET_INDEX = re.compile(r"^\s*([A-Za-z]?\s*\d{1,5})\s*\[\s*(\d{1,3})\s*\]\s*$")


def resolve(node: SessionNode, ref: str) -> Item:
    """A profile item, or for an index the profile does not list a raw item (read as bytes).

    Indexed parameters may be written ``P0700[1]`` (= ``P0700.1``); an index of a parameter the profile lists
    only as ``.0`` is found by the catalog (:meth:`Catalog.unlisted_index`).
    """
    bracket = _BRACKET_INDEX.match(ref)
    if bracket is not None:
        ref = f"{bracket.group(1)}.{bracket.group(2)}"
    catalog = _catalog(node)
    if catalog is not None:
        listed = _by_ref(catalog).get(ref.strip())
        if listed is not None:  # the ref as the table shows it (0x1003.10 is subindex 10 there, not 0x10)
            return listed
        try:
            return catalog.resolve(ref)
        except UnknownParameter:
            parsed = parse_ref(ref)
            indexed = catalog.unlisted_index(parsed)
            if indexed is not None:
                return indexed
            if not isinstance(parsed, IndexRef):
                raise
    parsed = parse_ref(ref)
    if not isinstance(parsed, IndexRef):
        raise UnknownParameter(_("Node {node} has no profile: address '{ref}' by its CANopen index (0x1018.1) or "
                                 "assign a profile").format(node=node.node_id, ref=ref))
    sub = parsed.subindex or 0
    entry = ObjectEntry(name="(not in the profile)", data_type=DataType.DOMAIN, access=Access.RW,
                        index=parsed.index, subindex=sub)
    name = f"0x{parsed.index:04X}" if sub == 0 else f"0x{parsed.index:04X}.{sub}"
    return Item(name, parsed.index, sub, entry)


_REFS: weakref.WeakKeyDictionary[Catalog, dict[str, Item]] = weakref.WeakKeyDictionary()


def _by_ref(catalog: Catalog) -> dict[str, Item]:
    refs = _REFS.get(catalog)
    if refs is None:
        refs = _REFS[catalog] = {item.ref: item for item in catalog.items}
    return refs


def items(node: SessionNode, query: str = "", group: str | None = None, parameter_set: int = 1) -> list[Item]:
    """The profile's items matching ``query``; an address the profile does not list (``0x2FFF.1``,
    ``P0700[1]``) gives the one item :func:`resolve` makes for it, so it can be read and written all the same.
    With ``parameter_set`` > 1 the codes the device keeps per set are those of that set (C0012 -> C2012)."""
    catalog = _catalog(node)
    if catalog is None:
        return []
    bracket = _BRACKET_INDEX.match(query)
    if bracket is not None:
        query = f"{bracket.group(1)}.{bracket.group(2)}"
    found = catalog.search(query) if query.strip() else catalog.items
    if not found and query.strip():
        with contextlib.suppress(UnknownParameter):
            found = [resolve(node, query)]
    return [catalog.in_set(item, parameter_set) for item in found if group is None or item.group == group]


def parameter_sets(node: SessionNode) -> int:
    """How many parameter sets the node's codes have (1 without a profile)."""
    catalog = _catalog(node)
    return catalog.parameter_sets if catalog is not None else 1


def groups(node: SessionNode) -> list[str]:
    """Groups in the manual's order, then any others the profile's items use."""
    catalog = _catalog(node)
    if catalog is None:
        return []
    ordered = list(catalog.profile.groups)
    for item in catalog.items:
        if item.group not in ordered:
            ordered.append(item.group)
    return ordered


# --- read ------------------------------------------------------------------------------------------------
def display(item: Item, scaled: ScaledValue) -> str:
    """What the table shows: ``10.20 A``, ``0 = 500 kbit/s``, ``0x00000644`` (a COB-ID, an identity, a bit-coded
    word: :func:`number_base.shows_hex`), ``01.00.00.00``."""
    entry = item.entry
    if isinstance(scaled.value, (int, float)) and not isinstance(scaled.value, bool):
        if scaled.text is not None and entry.selection:
            return f"{scaled.raw!s} = {scaled.text}"
        if isinstance(scaled.raw, int) and shows_hex(item):
            return hex_word(item, scaled.raw)
        decimals = entry.decimals if entry.factor != 1 else 0
        number = f"{scaled.value:.{decimals}f}" if decimals else f"{scaled.value}"
        if decimals > 2 and "." in number:  # FIX32 (factor 10000) is a format, not a resolution
            number = number.rstrip("0").rstrip(".")
        return f"{number} {entry.unit}" if entry.unit else number
    if isinstance(scaled.value, str) and entry.data_type is not DataType.VISIBLE_STRING:
        return scaled.value  # hex bytes
    return str(scaled.value) if scaled.value is not None else ""


class _Plan:
    """What reading one item needs, worked out once per item rather than once per read: the expedited request,
    an integer decoder, the name; and the scaled form of the last raw value read (scaling and formatting run
    again only when the value changes)."""

    __slots__ = ("_last", "_signed", "_size", "expedited", "item", "name", "on_loop", "request")

    def __init__(self, item: Item) -> None:
        entry = item.entry
        data_type = entry.data_type
        size = data_type.size
        self.item = item
        self.name = item.name
        self.expedited = size is not None and size <= 4 and entry.access.readable
        self.on_loop = entry.access.readable
        """Read on the event loop (:mod:`drivebench.protocol.canopen.sdo_fast`): expedited, or segmented for longer
        ones."""
        self.request = ExpeditedRequest(item.index, item.subindex)
        integer = data_type.is_integer and size is not None and data_type is not DataType.BOOLEAN
        self._size = size if integer else 0
        self._signed = data_type.is_signed
        self._last: tuple[RawValue, ScaledValue, str] | None = None

    def decode(self, data: bytes, node_id: int) -> RawValue:
        size = self._size
        if size and len(data) >= size:
            return int.from_bytes(data[:size], "little", signed=self._signed)
        return _decode(self.item, data, node_id)

    def value(self, raw: RawValue) -> ParameterValue:
        item = self.item
        last = self._last
        if last is None or type(last[0]) is not type(raw) or last[0] != raw:
            scaled = from_raw(item.entry, raw)
            last = self._last = (raw, scaled, display(item, scaled))
        scaled, shown = last[1], last[2]
        return ParameterValue(item.ref, self.name, item.index, item.subindex, scaled.raw, scaled.value, scaled.unit,
                              scaled.text, shown, time.time())


_PLANS: weakref.WeakKeyDictionary[Catalog, dict[int, _Plan]] = weakref.WeakKeyDictionary()
_RESOLVED: weakref.WeakKeyDictionary[Catalog, dict[str, _Plan]] = weakref.WeakKeyDictionary()
_CACHED_MAX = 4096
"""Plans and refs remembered per profile (refs as typed: ``C00088``, ``88``, ``0x5FA7sub0``); past that, work
them out each time."""


def _plan_of(catalog: Catalog | None, item: Item) -> _Plan:
    """The item's plan, cached per profile by the item's identity (items are not hashable; the plan holds its
    item, so a cached id is never reused by another object)."""
    if catalog is None:
        return _Plan(item)
    plans = _PLANS.get(catalog)
    if plans is None:
        plans = _PLANS[catalog] = {}
    plan = plans.get(id(item))
    if plan is None or plan.item is not item:
        plan = _Plan(item)
        if len(plans) < _CACHED_MAX:
            plans[id(item)] = plan
    return plan


def _plan(node: SessionNode, ref: str) -> _Plan:
    """:func:`resolve` and :func:`_plan_of`, remembered per profile and ref."""
    catalog = node.catalog
    if catalog is None:
        return _Plan(resolve(node, ref))
    known = _RESOLVED.get(catalog)
    if known is None:
        known = _RESOLVED[catalog] = {}
    plan = known.get(ref)
    if plan is None:
        plan = _plan_of(catalog, resolve(node, ref))
        if len(known) < _CACHED_MAX:
            known[ref] = plan
    return plan


def _decode(item: Item, data: bytes, node_id: int) -> RawValue:
    try:
        return decode(item.entry.data_type, data)
    except (ValueError, UnicodeDecodeError) as exc:  # a Text: a read-all job raises it too
        raise ProtocolError(Text(N_("Node {node}: {ref} answered {data}, which is not a {type}"), node=node_id,
                                 ref=item.ref, data=data.hex(" "), type=item.entry.data_type.value)) from exc


def _read_blocking(client: SdoClient, item: Item, *, block: bool = False, channel: int | None = None,
                   urgent: bool = False) -> bytes:
    if not item.entry.access.readable:
        raise InvalidValue(_("{ref} ({name}) is write-only").format(ref=item.ref, name=item.entry.name))
    return client.upload(item.index, item.subindex, block=block, channel=channel, urgent=urgent)


async def _upload(client: SdoClient, plan: _Plan, *, block: bool = False, channel: int | None = None,
                  on_loop: bool = True) -> bytes:
    """Read one value: expedited on the event loop where it can be (:mod:`drivebench.protocol.canopen.sdo_fast`), else
    canopen's client in a worker thread (``on_loop=False``: there at once, the device's answer on the loop was one
    only that client reads). Transfer errors name the parameter as the user knows it (C00099)."""
    try:
        if on_loop and plan.on_loop and not block and isinstance(client, NodeClient):  # CAN's fast path; CoE: its own
            data = await upload_expedited(client, plan.request, channel=channel, segmented=not plan.expedited,
                                          urgent=_urgent.get())
            if data is not None:
                return data
        return await _on_bus(partial(_read_blocking, client, plan.item, block=block, channel=channel,
                                     urgent=_urgent.get()))
    except (SdoStalledError, SdoOutOfStepError) as exc:
        raise exc.named(plan.item.ref) from exc


def _use_block(node: SessionNode, item: Item, transfer: str) -> bool:
    if transfer == "block":
        if node.profile is not None and not node.profile.features.block_sdo:
            raise InvalidValue(_("{device} does not support SDO block transfer").format(device=node.device_name))
        return True
    return False


_snapshot: ContextVar[dict[tuple[int, int, str, str], ParameterValue | DriveBenchError] | None] = ContextVar(
    "drivebench_read_snapshot", default=None)


@contextlib.contextmanager
def snapshot() -> Iterator[None]:
    """Inside, each parameter of a node is read from the device once: a second :func:`read` of it answers the
    first one's value (or raises its error). A shared status poll words one set of reads in several languages."""
    token = _snapshot.set({})
    try:
        yield
    finally:
        _snapshot.reset(token)


async def read(session: Session, node_id: int, ref: str, *, transfer: str = "auto") -> ParameterValue:
    """Read one parameter from the device. ``transfer``: ``auto`` (expedited/segmented as the size needs) or
    ``block`` (CiA 301 block upload)."""
    memo = _snapshot.get()
    if memo is not None:
        return await _read_once(memo, session, node_id, ref, transfer)
    node = session.node(node_id)
    plan = _plan(node, ref)
    block = transfer != "auto" and _use_block(node, plan.item, transfer)
    data = await _upload(session.client(node_id), plan, block=block)
    return _remembered(session, node_id, plan, data)


async def _read_once(memo: dict[tuple[int, int, str, str], ParameterValue | DriveBenchError], session: Session,
                     node_id: int, ref: str, transfer: str) -> ParameterValue:
    """:func:`read` inside :func:`snapshot`: the device is asked the first time only."""
    key = (id(session), node_id, ref, transfer)
    found = memo.get(key)
    if isinstance(found, DriveBenchError):
        raise found
    if found is not None:
        return found
    token = _snapshot.set(None)
    try:
        found = memo[key] = await read(session, node_id, ref, transfer=transfer)
    except DriveBenchError as exc:
        memo[key] = exc
        raise
    finally:
        _snapshot.reset(token)
    return found


def _remembered(session: Session, node_id: int, plan: _Plan, data: bytes) -> ParameterValue:
    value = plan.value(plan.decode(data, node_id))
    service(session).remember(node_id, value)
    return value


MAX_BATCH = 500
"""Refs one batch read may name (a whole Parameters group fits; a read of everything is a read-all job)."""


async def read_many(session: Session, node_id: int, refs: Sequence[str]) -> list[ParameterValue | DriveBenchError]:
    """Read ``refs`` and return, in their order, each value or the error that ref met: one unknown or refused ref
    does not lose the others. One SDO server answers one transfer at a time: the reads go one after the other, on
    CAN as one batch the bus reader thread sends request by request (:func:`sdo_fast.upload_batch`)."""
    node = session.node(node_id)  # an unknown node is the whole request's error, not one per ref
    if len(refs) > MAX_BATCH:
        raise InvalidValue(_("A batch read names at most {most} parameters; this one names {count}.").format(
            most=MAX_BATCH, count=len(refs)))
    found: list[ParameterValue | DriveBenchError | None] = [None] * len(refs)
    plans: dict[int, _Plan] = {}
    for position, ref in enumerate(refs):
        try:
            plans[position] = _plan(node, ref)
        except DriveBenchError as exc:
            found[position] = exc
    client = session.client(node_id)
    batched = [position for position, plan in plans.items() if plan.on_loop]
    if batched and isinstance(client, NodeClient):
        answers = await upload_batch(client, [plans[p].request for p in batched],
                                     [not plans[p].expedited for p in batched])
        for position, answer in zip(batched, answers or [], strict=False):
            plan = plans[position]
            if isinstance(answer, (SdoStalledError, SdoOutOfStepError)):
                found[position] = answer.named(plan.item.ref)
            elif isinstance(answer, DriveBenchError):
                found[position] = answer
            else:
                try:  # None: an answer only canopen's client reads; the device is not asked twice on the loop
                    data = answer if answer is not None else await _upload(client, plan, on_loop=False)
                    found[position] = _remembered(session, node_id, plan, data)
                except DriveBenchError as exc:
                    found[position] = exc
    for position, ref in enumerate(refs):  # the rest (a busy channel, CoE)
        if found[position] is None:
            try:
                found[position] = await read(session, node_id, ref)
            except DriveBenchError as exc:
                found[position] = exc
    return [result for result in found if result is not None]


# --- write -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WriteAttempt:
    """A write about to be sent: what the tool last read there (``old``, None if never read) and the new value."""

    session: Session
    node_id: int
    item: Item
    old: ParameterValue | None
    new: ScaledValue
    ctx: WriteContext
    """Who sends it and from where (the audit row's user and origin)."""


class WriteAudit(Protocol):
    """Told about every write :func:`write` sends: before sending, and with the outcome (the audit log)."""

    async def sending(self, attempt: WriteAttempt) -> object: ...

    async def done(self, token: object, result: WriteResult | None, error: BaseException | None) -> None: ...


class WriteAudits(list[WriteAudit]):
    """The session's :class:`WriteAudit` listeners (:attr:`SessionParameters.write_audits`)."""


@dataclass(frozen=True)
class MovingWrites:
    """How :func:`write` lets a write that can move the drive through: the drive guard's checks, given to the session
    when it opens (:meth:`drive_guard.Guard.moving_writes`), so this module needs nothing above it."""

    admit: Callable[[WriteContext, int, str, dict[str, object]], None]
    """The write's context, node id, what is written, the values sent (:func:`sent_values`): refused without the
    context's confirmation naming the node and repeating the values; arms the keep-alive for its panel."""
    stopped: Callable[[WriteContext, int], None]
    """The write's context, node id: a control word that stops the drive was written."""
    confirm: Callable[[WriteContext, int, str, dict[str, object]], WriteContext]
    """The context, node id, what will be written, the values: refused without the confirmation naming the node
    and repeating the values, nothing armed yet (a batch checks this before its first write); the context its writes
    then carry (with these values confirmed)."""


def sent_key(item: Item, unit: str | None = None) -> str:
    """How a confirmation names an object it writes: canonical ref, name, unit (``0x60FF Target velocity [rpm]``)."""
    unit = unit if unit is not None else item.entry.unit
    return f"{item.ref} {item.name}" + (f" [{unit}]" if unit else "")


def sent_values(item: Item, raw: RawValue) -> dict[str, object]:
    """What a write of ``raw`` sends, as a confirmation names it: the value in the units the user sees."""
    value: object = from_raw(item.entry, raw).value
    if isinstance(value, bytes):
        value = value.hex(" ")
    return {sent_key(item): value}


def sent_value(item: Item, value: object) -> dict[str, object]:
    """:func:`sent_values` of a write of ``value`` (as given), without the profile's range checks."""
    try:
        return sent_values(item, _unchecked_raw(item, value))
    except (DriveBenchError, ValueError):
        return {sent_key(item): value}


def _unchecked_raw(item: Item, value: object) -> RawValue:
    """The raw value without the profile's range/selection/read-only checks (the device decides); it must
    still fit the data type: nothing is ever truncated."""
    relaxed = item.entry.model_copy(update={"access": Access.RW, "min": None, "max": None, "selection": {}})
    return to_raw(relaxed, value, ref=item.ref)


def _same(item: Item, written: RawValue, read_back: RawValue) -> bool:
    if isinstance(written, float) and isinstance(read_back, (int, float)):
        return math.isclose(written, read_back, rel_tol=1e-6, abs_tol=1e-9)
    if isinstance(written, str) and isinstance(read_back, str):
        return written.rstrip("\x00") == read_back.rstrip("\x00")
    return written == read_back


def checked_raw(node: SessionNode, ref: str, value: object, *, check: bool = True) -> tuple[Item, RawValue]:
    """The item and the raw value a write of ``value`` sends, validated as :func:`write` validates it."""
    item = resolve(node, ref)
    return item, to_raw(item.entry, value, ref=item.ref) if check else _unchecked_raw(item, value)


def encoded(item: Item, raw: RawValue, value: object) -> bytes:
    """The bytes of ``raw`` in the item's data type (OutOfRange in words when it does not fit)."""
    try:
        return encode(item.entry.data_type, raw)
    except ValueError as exc:
        raise OutOfRange(_("{ref} ({name}): {value} does not fit {type}").format(
            ref=item.ref, name=item.entry.name, value=repr(value), type=item.entry.data_type.value)) from exc


def given_value(node: SessionNode, ref: str, value: object, raw: int | None) -> object:
    """What to write: ``value`` as given, or the device's integer ``raw`` in engineering units."""
    if raw is None:
        return value
    item = resolve(node, ref)
    return raw / item.entry.factor if item.entry.factor != 1 else raw


async def write(session: Session, node_id: int, ref: str, value: object, *, ctx: WriteContext, check: bool = True,
                verify: bool = True) -> WriteResult:
    """Validate, send, read back. ``value`` is what a user typed (``"10.2"``, ``"10.20 A"``, ``"500 kbit/s"``)
    or a number in engineering units. ``check=False`` leaves range, selection and read-only to the device.
    Refused (409) while another writer holds the node's lease (:mod:`drivebench.services.params.node_lease`); ``ctx``
    says who writes, from which panel, with which confirmation (:mod:`~drivebench.services.params.write_context`).

    A write that can make the drive move (:mod:`drivebench.device.drive.motion`: a control word, setpoint, mode ...)
    needs the confirmation naming the node and arms the keep-alive guard (:func:`drive_guard.admit_moving_write`);
    a control word that only stops the drive is never refused, by a lease or for a confirmation, and goes before the
    reads waiting for the node (:func:`stop_first`)."""
    node = session.node(node_id)
    item, raw = checked_raw(node, ref, value, check=check)
    verdict = judge(item, raw, node.profile)
    stops = verdict.stopping
    with node_lease.writing(session, node_id, ctx.stopping() if stops else ctx), \
            stop_first(session, node_id) if stops else contextlib.nullcontext():
        if verdict.moving:
            service(session).moving_writes.admit(ctx, node_id, f"Writing {item.ref} ({item.name}) = {value}",
                                                 sent_values(item, raw))
        result = await _write(session, node, item, raw, value, ctx, verify=verify)
    if verdict.stopping:
        service(session).moving_writes.stopped(ctx, node_id)
    return result


async def _write(session: Session, node: SessionNode, item: Item, raw: RawValue, value: object, ctx: WriteContext,
                 *, verify: bool) -> WriteResult:
    data = encoded(item, raw, value)
    return await _audited(session, node.node_id, item, raw, ctx,
                          partial(_send, session, node, item, raw, data, verify))


async def _audited(session: Session, node_id: int, item: Item, raw: RawValue, ctx: WriteContext,
                   send: Callable[[], Awaitable[WriteResult]]) -> WriteResult:
    """``send()`` between the session's :class:`WriteAudit` rows: one before it, completed with its outcome."""
    state = service(session)
    audits = state.write_audits
    if not audits:
        return await send()
    attempt = WriteAttempt(session, node_id, item, state.values.get(node_id, {}).get(item.ref),
                           from_raw(item.entry, raw), ctx)
    tokens = [(audit, await audit.sending(attempt)) for audit in audits]
    try:
        result = await send()
    except BaseException as exc:
        for audit, token in tokens:
            await asyncio.shield(audit.done(token, None, exc))
        raise
    for audit, token in tokens:
        await audit.done(token, result, None)
    return result


async def _download(session: Session, node_id: int, item: Item, data: bytes, shown: str) -> None:
    """Send ``data`` to the item. A node that never confirms it may have written the value and lost its answer:
    the item is read back once (the session's timeout and retries) and :class:`WriteOutcomeUnknown` says what the
    node holds, not that nothing happened."""
    client = session.client(node_id)
    urgent = _urgent.get()
    try:
        await _on_bus(lambda: client.download(item.index, item.subindex, data, urgent=urgent))
    except SdoTimeoutError as exc:
        raise await _unknown_outcome(session, node_id, item, shown) from exc


async def _unknown_outcome(session: Session, node_id: int, item: Item, shown: str) -> WriteOutcomeUnknown:
    words = {"node": node_id, "value": shown, "ref": f"{item.ref} ({item.name})"}
    held: str | None = None
    if not item.entry.access.readable:
        detail = Text(WriteOutcomeUnknown.WRITE_ONLY, **words)
    else:
        try:
            held = (await read(session, node_id, item.ref)).display
        except DriveBenchError as exc:
            detail = Text(WriteOutcomeUnknown.UNREAD, **words, why=said(exc))
        else:
            detail = Text(WriteOutcomeUnknown.HELD, **words, held=held)
    return WriteOutcomeUnknown(detail, node=node_id, index=item.index, subindex=item.subindex, read_back=held)


async def _send(session: Session, node: SessionNode, item: Item, raw: RawValue, data: bytes,
                verify: bool) -> WriteResult:
    node_id = node.node_id
    written = from_raw(item.entry, raw)
    await _download(session, node_id, item, data, display(item, written))
    if item.entry.reset_required:
        node.pending_reset.add(item.ref)
    read_back: ParameterValue | None = None
    verified: bool | None = None
    mismatch = None
    if verify and item.entry.access.readable:
        read_back = await read(session, node_id, item.ref)
        verified = _same(item, raw, read_back.raw)
        if not verified:
            mismatch = Text(N_("Wrote {written}, the device reports {reported} (takes effect after reset node)")
                             if item.entry.reset_required else N_("Wrote {written}, the device reports {reported}"),
                             written=display(item, written), reported=read_back.display)
    return WriteResult(item.ref, written, read_back, verified, mismatch, item.entry.reset_required)


_SIZED = {1: DataType.UNSIGNED8, 2: DataType.UNSIGNED16, 4: DataType.UNSIGNED32}


def _object_at(node: SessionNode, index: int, subindex: int, size: int) -> Item:
    """The profile's item at the address, else one named by its index with the data's unsigned type."""
    catalog = _catalog(node)
    listed = catalog.by_address(index, subindex) if catalog is not None else None
    if listed is not None:
        return listed
    entry = ObjectEntry(name="(not in the profile)", data_type=_SIZED.get(size, DataType.DOMAIN), access=Access.RW,
                        index=index, subindex=subindex)
    return Item(f"0x{index:04X}" if subindex == 0 else f"0x{index:04X}.{subindex}", index, subindex, entry)


async def send_logged(session: Session, node_id: int, index: int, subindex: int, data: bytes, *,
                      ctx: WriteContext, verify: bool = False) -> WriteResult:
    """A download a service sends itself rather than through :func:`write` (a PDO configuration step, the heartbeat
    time, SDO2's COB-IDs): in the audit log like every write, with ``ctx``'s user and origin, read back with
    ``verify``. A lost answer is :class:`WriteOutcomeUnknown` as in :func:`write`. The caller holds the
    node's lease and checked the value."""
    node = session.node(node_id)
    item = _object_at(node, index, subindex, len(data))
    try:
        raw: RawValue = decode(item.entry.data_type, data)
    except (ValueError, UnicodeDecodeError):
        raw = int.from_bytes(data, "little")
    return await _audited(session, node_id, item, raw, ctx, partial(_send, session, node, item, raw, data, verify))


# --- device commands -------------------------------------------------------------------------------------
def _find(catalog: Catalog | None, *refs: str) -> Item | None:
    if catalog is None:
        return None
    for ref in refs:
        try:
            item = catalog.resolve(ref)
        except UnknownParameter:
            continue
        if item.entry.access.writable:
            return item
    return None


def _command_write(node: SessionNode, catalog: Catalog | None, which: DeviceCommand) -> CommandWrite | None:
    """The profile's own write for ``which`` (its ``commands`` section), else CiA 301's where the device has it."""
    section = node.profile.commands if node.profile is not None else None
    own = None if section is None else section.save if which is DeviceCommand.SAVE else section.restore_defaults
    if own is not None:
        return own
    standard = CIA301_SAVE if which is DeviceCommand.SAVE else CIA301_RESTORE
    return standard if catalog is None or _find(catalog, standard.ref) is not None else None


async def command(session: Session, node_id: int, which: DeviceCommand, *, ctx: WriteContext) -> CommandResult:
    session.node(node_id)
    with node_lease.writing(session, node_id, ctx):
        return await _command(session, node_id, which, ctx)


async def _command(session: Session, node_id: int, which: DeviceCommand, ctx: WriteContext) -> CommandResult:
    node = session.node(node_id)
    catalog = _catalog(node)
    client = session.client(node_id)
    if which is DeviceCommand.RESET_NODE:
        await session.nmt(NmtCommand.RESET_NODE, node_id)
        return CommandResult(which, "NMT reset node",
                             Text(N_("Node {node} resets; unsaved changes are lost."), node=node_id))
    write = _command_write(node, catalog, which)
    if write is None:
        raise Conflict(_("{device} offers no {command} command in its profile (no CiA 301 object, no commands "
                         "section)").format(device=node.device_name, command=_command_name(which)))
    item = _find(catalog, write.ref)
    if item is not None:
        index, subindex, data = item.index, item.subindex, encode(item.entry.data_type, write.raw)
        if judge(item, write.raw, node.profile).moving:  # a profile's command is a write like any other
            service(session).moving_writes.admit(ctx, node_id, _("The {command} command ({via})").format(
                command=_command_name(which), via=write.via), sent_values(item, write.raw))
    elif catalog is None:  # no profile: the CiA 301 object, addressed as such
        parsed = parse_ref(write.ref)
        assert isinstance(parsed, IndexRef)  # CIA301_SAVE / CIA301_RESTORE
        index, subindex, data = parsed.index, parsed.subindex or 0, write.raw.to_bytes(4, "little")
    else:
        raise Conflict(_("{device}: the profile's {command} command writes {ref}, which the profile does not list as "
                         "a writable entry").format(device=node.device_name, command=_command_name(which),
                                                    ref=write.ref))
    await _on_bus(partial(client.download, index, subindex, data))
    if write.after_reset:
        node.pending_reset.add("restore defaults")
    return CommandResult(which, write.via, Text(write.done, node=node_id))


def _command_name(which: DeviceCommand) -> str:
    return {DeviceCommand.SAVE: _("save"), DeviceCommand.RESTORE_DEFAULTS: _("restore defaults"),
            DeviceCommand.RESET_NODE: _("reset node")}[which]


# --- second SDO channel ----------------------------------------------------------------------------------


def _sdo2_check_blocking(session: Session, node: SessionNode) -> tuple[_NodeChannels, tuple[int, int] | None]:
    """The node's channel state, with SDO2 in use where it is on in the node already; where the profile's first
    additional SDO server (its ``sdo_channels`` section) is off and safe to use, the COB-IDs to switch it on with."""
    state = service(session)
    channels = state.channels.setdefault(node.node_id, _NodeChannels())
    if channels.active:
        return channels, None
    catalog = _catalog(node)
    profile = node.profile
    if (not state.settings.use_sdo2 or catalog is None or profile is None or not profile.sdo_channels
            or profile.features.transport != "canopen"):
        return channels, None
    extra = profile.sdo_channels[0]
    index = extra.parameter_index
    rx_item, tx_item = catalog.by_address(index, 1), catalog.by_address(index, 2)
    if rx_item is None or tx_item is None or not rx_item.entry.access.writable:
        return channels, None
    clash = extra.clashes_with(node.node_id)
    if node.node_id > extra.max_node_id or clash in session.nodes:
        channels.note = Text(N_("SDO{number} not used on node {node}: its identifiers would be node {other}'s SDO1"),
                              number=extra.number, node=node.node_id, other=clash)
        return channels, None
    client = session.client(node.node_id)
    if not isinstance(client, NodeClient):  # an EtherCAT slave has one mailbox
        return channels, None
    rx, tx = (int.from_bytes(client.upload(index, sub, channel=1)[:4], "little") for sub in (1, 2))
    if rx & 0x80000000 or tx & 0x80000000 or not rx or not tx:
        return channels, extra.cob_ids(node.node_id)
    _use_sdo2(client, channels, rx, tx)
    return channels, None


def _use_sdo2(client: NodeClient, channels: _NodeChannels, rx: int, tx: int) -> None:
    if channels.sdo2 is None:
        channels.sdo2 = client.add_channel(rx & 0x7FF, tx & 0x7FF)
    elif channels.sdo2 not in client.channels:
        client.channels.append(channels.sdo2)
    channels.active = True


async def _activate_sdo2(session: Session, node: SessionNode, ctx: WriteContext) -> _NodeChannels:
    """Switch on the profile's first additional SDO server where that is safe (the writes in the audit log with the
    origin of whoever reads: a read-all, a parameter-set download reading the values before it writes)."""
    channels, switch_on = await _on_bus(lambda: _sdo2_check_blocking(session, node))
    if switch_on is None or node.profile is None:
        return channels
    extra = node.profile.sdo_channels[0]
    rx, tx = switch_on
    for sub, cob_id in ((1, rx), (2, tx)):  # client -> server first, then server -> client (the manuals' 0x1201)
        await send_logged(session, node.node_id, extra.parameter_index, sub, cob_id.to_bytes(4, "little"),
                          ctx=ctx, verify=True)
    channels.note = Text(N_("SDO{number} activated on node {node} ({rx}/{tx}, not saved)"), number=extra.number,
                          node=node.node_id, rx=f"0x{rx:03X}", tx=f"0x{tx:03X}")
    client = session.client(node.node_id)
    assert isinstance(client, NodeClient)  # checked by _sdo2_check_blocking
    _use_sdo2(client, channels, rx, tx)
    return channels


async def sdo_channels(session: Session, node: SessionNode, ctx: WriteContext) -> list[int]:
    """The channel numbers to spread reads over (SDO2 activated first where possible; asked twice when it times
    out, as one late answer on a busy machine would otherwise halve the read-all's speed)."""
    for attempt in range(2):
        try:
            channels = await _activate_sdo2(session, node, ctx)
        except SdoTimeoutError:
            if attempt:
                return [1]
            continue
        except (SdoAbortError, ProtocolError):
            return [1]
        return [1, 2] if channels.active else [1]
    return [1]


# --- read-all ---------------------------------------------------------------------------------------------
def readable_items(node: SessionNode, group: str | None = None, parameter_set: int = 1) -> list[Item]:
    return [item for item in items(node, group=group, parameter_set=parameter_set) if item.entry.access.readable]


def _issue(node_id: int, item: Item, exc: Exception) -> JobIssue:
    detail = said(exc)
    if isinstance(exc, SdoAbortError):
        return JobIssue(item.ref, detail, node_id, f"0x{exc.abort_code:08X}", exc.abort_text)
    return JobIssue(item.ref, detail, node_id)


_DEVICE_TYPE = _Plan(Item("0x1000", 0x1000, 0, ObjectEntry(name="Device type", data_type=DataType.UNSIGNED32,
                                                             access=Access.RO, index=0x1000, subindex=0)))
"""What a silence probe reads: CiA 301 0x1000, mandatory on every device."""


def _silence(session: Session, client: SdoClient, channel: int) -> NodeSilence:
    return NodeSilence(client.node_id, partial(_upload, client, _DEVICE_TYPE, channel=channel), session.heartbeat)


def silence_watch(session: Session, node_id: int) -> NodeSilence:
    """Evidence whether the node has gone silent, for a long job that writes or reads it on its first channel."""
    return _silence(session, session.client(node_id), 1)


async def read_node(session: Session, node: SessionNode, work: list[Item], job: Job, ctx: WriteContext) -> None:
    """Read the items over the node's SDO channels (``ctx``: whose writes switch its SDO2 on). A read that times out
    is asked again at the end; the node is given up only when :class:`NodeSilence` judges it silent (not after two
    slow answers)."""
    state = service(session)
    client = session.client(node.node_id)
    key = str(node.node_id)
    values: dict[str, object] = job.result.setdefault("values", {}).setdefault(key, {})
    channel_numbers = await sdo_channels(session, node, ctx)
    note = state.channels.get(node.node_id)
    if note is not None and note.note and note.note not in job.notes:
        job.notes.append(note.note)
    silence = _silence(session, client, channel_numbers[0])
    timed_out: dict[str, tuple[Item, Exception]] = {}

    def failed(item: Item, exc: Exception) -> None:
        issue = _issue(node.node_id, item, exc)
        state.not_read(node.node_id, item.ref, issue.detail)
        job.advance(issue=issue)

    retried: list[str] = []
    failed_again: list[str] = []

    async def drain(queue: deque[Item], channel: int, last_pass: bool) -> None:
        while queue and silence.verdict is None:
            item = queue.popleft()
            try:
                plan = _plan_of(node.catalog, item)
                data = await _upload(client, plan, channel=channel)
                value = plan.value(plan.decode(data, node.node_id))
            except (SdoTimeoutError, SdoOutOfStepError) as exc:
                if last_pass:
                    failed_again.append(item.ref)
                    failed(item, exc)
                else:
                    timed_out[item.ref] = (item, exc)  # counted when asked again (or given up)
                await silence.timed_out(exc)
                continue
            except (ProtocolError, InvalidValue) as exc:
                failed(item, exc)
                continue
            silence.answered()
            state.remember(node.node_id, value)
            values[item.ref] = value
            job.advance()

    queue = deque(work)
    await asyncio.gather(*(drain(queue, channel, False) for channel in channel_numbers))
    if timed_out and silence.verdict is None:
        again = deque(item for item, _error in timed_out.values())
        retried.extend(item.ref for item in again)
        timed_out.clear()
        await asyncio.gather(*(drain(again, channel, True) for channel in channel_numbers))
        queue.extend(again)  # left over if the node fell silent meanwhile
    if retried:
        job.result.setdefault("retried", {})[key] = retried
        job.result.setdefault("failed_after_retry", {})[key] = failed_again
        job.notes.append(Text(N_("Node {node}: {count} parameters timed out and were asked again at the end, "
                                  "{answered} of them answered"), node=node.node_id, count=len(retried),
                               answered=len(retried) - len(failed_again)))
    if silence.verdict is not None:
        for item, exc in timed_out.values():
            failed(item, exc)
        given_up = Text(N_("Node {node} {verdict}; {count} parameters not read"), node=node.node_id,
                        verdict=Text(silence.verdict), count=len(queue))
        job.notes.append(given_up)
        for item in queue:
            state.not_read(node.node_id, item.ref, given_up)
        job.give_up(len(queue))


def start_read(session: Session, node_ids: Iterable[int], jobs: JobManager, *, ctx: WriteContext,
               group: str | None = None, parameter_set: int = 1) -> Job:
    """A job reading every readable parameter (or one group) of the nodes, the codes kept per parameter set in
    ``parameter_set``; different nodes in parallel. What it writes (a node's SDO2 switched on) is ``ctx``'s, with
    the origin ``read-all``."""
    ctx = ctx.as_origin(READ_ALL_ORIGIN)
    nodes = [session.node(node_id) for node_id in node_ids]
    work = {node.node_id: readable_items(node, group, parameter_set) for node in nodes}
    if group is not None and not any(work.values()):
        raise UnknownParameter(_("No readable parameters in group '{group}'").format(group=group))
    total = sum(len(found) for found in work.values())
    if len(nodes) == 1:
        title = (Text(N_("Read group '{group}' of node {node}"), group=group, node=nodes[0].node_id) if group
                 else Text(N_("Read all parameters of node {node}"), node=nodes[0].node_id))
    else:
        title = (Text(N_("Read group '{group}' of {count} nodes"), group=group, count=len(nodes)) if group
                 else Text(N_("Read all parameters of {count} nodes"), count=len(nodes)))

    async def run(job: Job) -> None:
        job.result["values"] = {}
        try:
            await asyncio.gather(*(read_node(session, node, work[node.node_id], job, ctx) for node in nodes))
        except TransportError as exc:  # the adapter is gone: stop, keep what was read, say how far it got
            read = sum(len(values) for values in job.result["values"].values())
            raise TransportError(Text(N_("{why}, {read} of {total} parameters read before"), why=said(exc),
                                      read=read, total=total), hint=exc.hint) from exc

    # The same read asked again while it runs follows the running job (a read-all is minutes of bus work per node).
    same_as = f"read {session.id} {sorted(work)} {group or '*'} {parameter_set}"
    return jobs.start("read", title, total, run, same_as=same_as, failures_leave_incomplete=True)
