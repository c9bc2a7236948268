"""Writing parameters: a write is validated against the profile before anything is sent (type width, range,
selection list, read-only), then read back and compared (verify). Values that take effect only after reset node
are flagged on the node until it boots again. Every write goes through the session's audit listeners, and one that
can move the drive through the drive guard's checks (:mod:`drivebench.services.params.write_ports`)."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Awaitable, Callable
from functools import partial

from drivebench.device.drive.motion import judge
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.device.profiles.scaling import RawValue, from_raw, to_raw
from drivebench.errors import DriveBenchError, OutOfRange, SdoTimeoutError, WriteOutcomeUnknown
from drivebench.i18n import N_, Text, _
from drivebench.protocol.datatypes import DataType, decode, encode
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import node_lease
from drivebench.services.params.jobs import said
from drivebench.services.params.lookup import resolve
from drivebench.services.params.reads import display, read
from drivebench.services.params.session_part import on_bus, service, stop_first, urgent
from drivebench.services.params.values import ParameterValue, WriteResult
from drivebench.services.params.write_context import WriteContext
from drivebench.services.params.write_ports import WriteAttempt


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
    is_urgent = urgent()
    try:
        await on_bus(lambda: client.download(item.index, item.subindex, data, urgent=is_urgent))
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
    catalog = node.catalog
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

