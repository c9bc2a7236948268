"""Reading parameters: values come back scaled, with unit, selection text or named bits (``C00088`` raw 1020 ->
10.20 A). One read, a batch of reads (:func:`read_many`), and the read plans behind them (:class:`Plan`: what
reading one item needs, worked out once per item)."""

from __future__ import annotations

import contextlib
import time
import weakref
from collections.abc import Iterator, Sequence
from contextvars import ContextVar
from functools import partial

from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.number_base import hex_word, shows_hex
from drivebench.device.profiles.scaling import RawValue, ScaledValue, from_raw
from drivebench.errors import DriveBenchError, InvalidValue, ProtocolError, SdoOutOfStepError, SdoStalledError
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.sdo_fast import ExpeditedRequest, upload_batch, upload_expedited
from drivebench.protocol.datatypes import DataType, decode
from drivebench.services.bus.fieldbus import SdoClient
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params.lookup import resolve
from drivebench.services.params.session_part import on_bus, service, urgent
from drivebench.services.params.values import ParameterValue


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


class Plan:
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


_PLANS: weakref.WeakKeyDictionary[Catalog, dict[int, Plan]] = weakref.WeakKeyDictionary()
_RESOLVED: weakref.WeakKeyDictionary[Catalog, dict[str, Plan]] = weakref.WeakKeyDictionary()
_CACHED_MAX = 4096
"""Plans and refs remembered per profile (refs as typed: ``C00088``, ``88``, ``0x5FA7sub0``); past that, work
them out each time."""


def plan_of(catalog: Catalog | None, item: Item) -> Plan:
    """The item's plan, cached per profile by the item's identity (items are not hashable; the plan holds its
    item, so a cached id is never reused by another object)."""
    if catalog is None:
        return Plan(item)
    plans = _PLANS.get(catalog)
    if plans is None:
        plans = _PLANS[catalog] = {}
    plan = plans.get(id(item))
    if plan is None or plan.item is not item:
        plan = Plan(item)
        if len(plans) < _CACHED_MAX:
            plans[id(item)] = plan
    return plan


def _plan(node: SessionNode, ref: str) -> Plan:
    """:func:`resolve` and :func:`plan_of`, remembered per profile and ref."""
    catalog = node.catalog
    if catalog is None:
        return Plan(resolve(node, ref))
    known = _RESOLVED.get(catalog)
    if known is None:
        known = _RESOLVED[catalog] = {}
    plan = known.get(ref)
    if plan is None:
        plan = plan_of(catalog, resolve(node, ref))
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


async def upload(client: SdoClient, plan: Plan, *, block: bool = False, channel: int | None = None,
                 on_loop: bool = True) -> bytes:
    """Read one value: expedited on the event loop where it can be (:mod:`drivebench.protocol.canopen.sdo_fast`), else
    canopen's client in a worker thread (``on_loop=False``: there at once, the device's answer on the loop was one
    only that client reads). Transfer errors name the parameter as the user knows it (C00099)."""
    try:
        if on_loop and plan.on_loop and not block and client.fast_path is not None:  # CAN's; CoE: worker thread
            data = await upload_expedited(client.fast_path, plan.request, channel=channel, segmented=not plan.expedited,
                                          urgent=urgent())
            if data is not None:
                return data
        return await on_bus(partial(_read_blocking, client, plan.item, block=block, channel=channel,
                                    urgent=urgent()))
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
    data = await upload(session.client(node_id), plan, block=block)
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


def _remembered(session: Session, node_id: int, plan: Plan, data: bytes) -> ParameterValue:
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
    plans: dict[int, Plan] = {}
    for position, ref in enumerate(refs):
        try:
            plans[position] = _plan(node, ref)
        except DriveBenchError as exc:
            found[position] = exc
    client = session.client(node_id)
    batched = [position for position, plan in plans.items() if plan.on_loop]
    if batched and client.fast_path is not None:
        answers = await upload_batch(client.fast_path, [plans[p].request for p in batched],
                                     [not plans[p].expedited for p in batched])
        for position, answer in zip(batched, answers or [], strict=False):
            plan = plans[position]
            if isinstance(answer, (SdoStalledError, SdoOutOfStepError)):
                found[position] = answer.named(plan.item.ref)
            elif isinstance(answer, DriveBenchError):
                found[position] = answer
            else:
                try:  # None: an answer only canopen's client reads; the device is not asked twice on the loop
                    data = answer if answer is not None else await upload(client, plan, on_loop=False)
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

