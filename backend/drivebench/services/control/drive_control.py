"""Drive control panel: state from the status word, transitions, setpoint in user units, jog, modes, actual values.

Safety interlocks (the access-control issue's rules): every command after which the motor may turn needs
``confirm`` naming the node (its id, see :func:`drive_guard.require_confirmation`; else 428); once such a command
was sent the node is *armed*: the client must send keep-alives (websocket message or POST) at least every
:data:`KEEPALIVE_TIMEOUT_S`; when they stop, or the panel's websocket closes, the
server sends quick stop. Shutdown, disable and quick stop disarm.

Several panels on one node: the panel that armed the drive *holds* it until the drive is disarmed. Only the holder
moves it (enable, setpoint, jog, mode, fault reset, commissioning steps) and only its keep-alives count; closing the
holder's last websocket quick-stops. Every other panel watches: it sees who holds the drive and since when, and it
may still stop the drive (quick stop, disable, shutdown), as any station of a machine may - which disarms it.

The guard itself (arming, holders, keep-alive deadlines, quick stop) is :mod:`drivebench.services.control.drive_guard`.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import TypeVar

from pydantic import BaseModel

from drivebench.device.drive import cia402
from drivebench.device.drive.control import ActualSpec, Setpoint, WordScale
from drivebench.device.drive.control import JogPlan as JogSpec
from drivebench.device.profiles.catalog import Catalog
from drivebench.errors import Conflict, DriveBenchError, InvalidValue, OutOfRange, UnknownParameter
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control import soft_limits
from drivebench.services.control.drive_guard import (
    ARM_SETTLE_S,
    SERVICE_PANEL,
    Panel,
    Values,
    guard_for,
    last_word,
    read_word,
    require_confirmation,
    write_word,
)
from drivebench.services.control.drive_units import generic_limits as _generic_limits
from drivebench.services.control.drive_units import motion_units
from drivebench.services.control.drive_words import (
    Command,
    Family,
    command_label,
    family_of,
    next_control_word,
    state_label,
)
from drivebench.services.monitoring import fault_words
from drivebench.services.monitoring.diagnostics import EmcyRecord
from drivebench.services.params.write_context import WriteContext
from drivebench.services.pdos import process_data as live

# the rest of the guard's surface, re-exported for this module's callers (web api/ws/pages, tests)
from drivebench.services.control.drive_guard import KEEPALIVE_TIMEOUT_S as KEEPALIVE_TIMEOUT_S  # isort: skip
from drivebench.services.control.drive_guard import Guard as Guard  # isort: skip
from drivebench.services.control.drive_guard import Holder as Holder  # isort: skip
from drivebench.services.control.drive_guard import panel_of as panel_of  # isort: skip
from drivebench.services.params import reads, session_part, writes


# --- setpoint and actual values --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scale:
    """User value = raw / raw_per_unit (a process-data word) or the profile's own scaling (raw_per_unit 0)."""

    ref: str
    unit: str
    raw_per_unit: float = 0.0
    minimum: float | None = None
    maximum: float | None = None


def has_ref(catalog: Catalog, ref: str) -> bool:
    try:
        catalog.resolve(ref)
    except UnknownParameter:
        return False
    return True


def catalog_of(node: SessionNode) -> Catalog:
    if node.catalog is None:
        raise InvalidValue(_("Node {node} has no device profile: the control panel needs one.").format(
            node=node.node_id))
    return node.catalog


def family(node: SessionNode) -> Family:
    found = family_of(node.catalog)
    if found is None:
        raise InvalidValue(_("{device} has no device control word DriveBench knows: its profile has no control "
                             "section and its object dictionary no CiA 402 control/status word (0x6040/0x6041).")
                           .format(device=node.device_name))
    return found


async def _number(session: Session, node: SessionNode, ref: str | None, default: float) -> float:
    if ref is None or not has_ref(catalog_of(node), ref):
        return default
    value = (await reads.read(session, node.node_id, ref)).value
    return float(value) if isinstance(value, (int, float)) else default


async def _raw_per_unit(session: Session, node: SessionNode, scale: WordScale | None) -> tuple[float, float]:
    """(raw per unit, reference value) of a process-data word; (0, 0) for the entry's own scaling."""
    if scale is None:
        return 0.0, 0.0
    if scale.raw_per_unit:
        return scale.raw_per_unit, 0.0
    reference = await _number(session, node, scale.reference_ref, scale.reference_default) or scale.reference_default
    return (scale.full_scale_raw or 1) / reference, reference


def _setpoint(fam: Family, mode: int | None) -> Setpoint:
    for spec in fam.section.setpoints:
        if mode in spec.modes:
            return spec
    found = next((spec for spec in fam.section.setpoints if not spec.modes), None)
    if found is None:
        shown = mode_label(fam, mode) if mode is not None else _("none")
        raise InvalidValue(_("The mode of operation shown ({mode}) takes no setpoint from this panel: choose "
                             "another mode.").format(mode=shown))
    return found


async def setpoint_scale(session: Session, node: SessionNode, mode: int | None) -> Scale:
    fam = family(node)
    try:
        spec = _setpoint(fam, mode)
    except InvalidValue:
        return Scale("", "")
    raw_per_unit, reference = await _raw_per_unit(session, node, spec.scale)
    unit = spec.unit
    if unit in ("position", "velocity"):
        unit = getattr(await motion_units(session, node), unit)
    low, high = spec.min, spec.max
    if spec.limit_ref is not None:
        top = await _number(session, node, spec.limit_ref, spec.max or 0.0)
        low, high = -top, top
    elif spec.limit_times_reference is not None:
        low, high = -spec.limit_times_reference * reference, spec.limit_times_reference * reference
    elif fam.generic:
        low, high = await _generic_limits(session, node, spec.ref)
    return Scale(spec.ref, unit, raw_per_unit, low, high)


def actual_refs(node: SessionNode) -> list[ActualSpec]:
    """The actual values of the profile's control section this device has."""
    fam, catalog = family(node), catalog_of(node)
    return [spec for spec in fam.section.actual_values if has_ref(catalog, spec.ref)]


def missing_actuals(node: SessionNode) -> list[str]:
    """The kinds of actual value the panel plots elsewhere that this device's profile (and its manual) lacks."""
    present = {spec.label.split(" (")[0] for spec in actual_refs(node)}
    return [cia402.shown(kind) for kind in family(node).section.actual_kinds if kind not in present]


def missing_why(node: SessionNode) -> str:
    """Why the values :func:`missing_actuals` names are not there: which manual was searched for what."""
    return cia402.shown(family(node).section.missing_why)


def actual_source(node: SessionNode, ref: str, raw_per_unit: float = 0.0, unit: str | None = None) -> str:
    """Where a plotted value comes from: the object it is read from, its coding, and the manual that names it."""
    catalog = catalog_of(node)
    item = catalog.resolve(ref)
    coding = item.entry.data_type.name
    if raw_per_unit:
        coding += f", {unit} = " + _("raw / {factor}").format(factor=f"{raw_per_unit:g}")
    elif item.entry.factor != 1:
        coding += ", " + _("value = raw / {factor}").format(factor=f"{item.entry.factor:g}")
    text = item.entry.description or ""
    if text.startswith("Source: "):
        manual = text[len("Source: "):].split(". ")[0].rstrip(".")
    elif family(node).generic:
        manual = _("CiA 402-2 object")
    else:
        manual = catalog.profile.source.split(", ")[0] if catalog.profile.source else _("this device's profile")
    return f"{ref} = 0x{item.index:04X}.{item.subindex} ({coding}); {manual}"


async def actual_sources(session: Session, node: SessionNode) -> list[tuple[str, str]]:
    """(label, where it comes from) of every plotted actual value."""
    out = []
    for spec in actual_refs(node):
        raw_per_unit, _ = await _raw_per_unit(session, node, spec.scale)
        out.append((cia402.shown(spec.label), actual_source(node, spec.ref, raw_per_unit, spec.unit)))
    return out


class ActualValue(BaseModel):
    label: str
    ref: str
    value: float | None
    unit: str | None
    error: str | None = None
    source: str | None = None
    """The object it is read from, its coding, and the manual that names it (see :func:`actual_source`)."""


def _signed16(raw: int) -> int:
    return raw - 0x10000 if raw >= 0x8000 else raw


async def read_actuals(session: Session, node: SessionNode) -> list[ActualValue]:
    out: list[ActualValue] = []
    units = await motion_units(session, node) if family(node).generic else None
    for spec in actual_refs(node):
        raw_per_unit, _ = await _raw_per_unit(session, node, spec.scale)
        source = actual_source(node, spec.ref, raw_per_unit, spec.unit)
        try:
            value = await reads.read(session, node.node_id, spec.ref)
        except DriveBenchError as exc:
            out.append(ActualValue(label=cia402.shown(spec.label), ref=spec.ref, value=None, unit=None,
                                   error=exc.shown_detail(), source=source))
            continue
        if raw_per_unit and isinstance(value.raw, int):
            out.append(ActualValue(label=cia402.shown(spec.label), ref=spec.ref, unit=spec.unit, source=source,
                                   value=round(_signed16(value.raw & 0xFFFF) / raw_per_unit, spec.decimals)))
            continue
        number = round(value.value, 3) if isinstance(value.value, (int, float)) else None  # REAL32 noise
        unit = value.unit or (cia402.shown(spec.unit) if spec.unit else None)
        if units is not None:
            unit = units.of(spec.ref) or unit
        out.append(ActualValue(label=cia402.shown(spec.label), ref=spec.ref, value=number, unit=unit, source=source))
    return out

# --- status --------------------------------------------------------------------------------------------------
class Bit(BaseModel):
    bit: int
    name: str
    set: bool


class StateOut(BaseModel):
    key: str
    label: str
    col: int
    row: int
    enabled: bool
    fault: bool


class DriveStatus(BaseModel):
    node_id: int
    family: str
    title: str
    note: str
    state: str
    state_label: str
    enabled: bool
    fault: bool
    status_ref: str
    status_word: int
    status_bits: list[Bit]
    control_ref: str
    control_word: int | None
    control_bits: list[Bit]
    commands: dict[str, str]
    moving_commands: list[str]
    states: list[StateOut]
    mode: int | None
    mode_label: str | None
    modes: dict[int, str]
    setpoint_ref: str
    setpoint_unit: str
    setpoint_min: float | None
    setpoint_max: float | None
    armed: bool
    holder: str | None
    """Who holds the armed drive, and since when (None: nobody, any panel may arm it)."""
    you_hold: bool
    """The panel asking is the holder (False for watchers and while nobody holds the drive)."""
    panels: int
    """Control panels (websockets) open on this node."""
    last_trip: str | None
    generic: bool = False
    """Standard CiA 402 control (no vendor section): the panel offers the motion controls (see ``motion``)."""
    inputs: list[Bit] = []
    """CiA 402 digital inputs 0x60FD (limit switches, home switch named), where the device has them."""
    error_code: int | None = None
    error_text: str | None = None
    """CiA 402 0x603F error code, decoded with the CiA 402 error-code table."""
    present_fault: EmcyRecord | None = None
    unread: dict[str, str] = {}
    """Values the drive refused to give (object -> the reason in words): the panel shows the rest and marks these."""
    """The emergency still active on the node, with the device's own fault number in the manual's words (from the
    EMCY consumer: no bus traffic)."""
    command_note: str | None = None
    """Why the command just sent may do nothing (the drive takes its commands from elsewhere; profile
    ``faults.command_source``)."""
    limit_note: str | None = None
    """How the last jog, velocity or relative move ended at a software position limit 0x607D: the drive clamped
    (0x6041 bit 11) or DriveBench halted it (``services/control/soft_limits.py``)."""


def bits(names: dict[int, str], word: int | None) -> list[Bit]:
    return [Bit(bit=bit, name=cia402.shown(names[bit]) if bit in names else _("Bit {bit}").format(bit=bit),
                set=bool(word is not None and word >> bit & 1)) for bit in range(16)]


def describe(fam: Family, status_word: int) -> tuple[str, str, bool, bool]:
    """(state key, label, enabled?, fault?) for a status word."""
    key = fam.state_of(status_word)
    box = fam.state_box(key)
    return key, state_label(fam, key), bool(box and box.enabled), bool(box and box.fault)


def mode_label(fam: Family, mode: int) -> str:
    named = fam.section.modes.get(mode)
    return cia402.shown(named) if named else cia402.mode_label(mode)


async def _mode(session: Session, node: SessionNode) -> int | None:
    shown = cia402.MODES_OF_OPERATION_DISPLAY
    if family(node).section.state_machine != "cia402" or not has_ref(catalog_of(node), shown):
        return None
    raw = (await reads.read(session, node.node_id, shown)).raw
    return int(raw) if isinstance(raw, int) else None


async def modes(session: Session, node: SessionNode) -> dict[int, str]:
    """The modes the panel offers: the section's, for a generic drive those 0x6502 names (else its EDS lists)."""
    fam = family(node)
    if fam.generic and has_ref(catalog_of(node), cia402.SUPPORTED_DRIVE_MODES):
        raw = (await reads.read(session, node.node_id, cia402.SUPPORTED_DRIVE_MODES)).raw
        if isinstance(raw, int):
            return {mode: cia402.mode_label(mode) for mode in cia402.modes_from_6502(raw)}
    return section_modes(fam)


def section_modes(fam: Family) -> dict[int, str]:
    """The modes the profile's control section names."""
    return {mode: cia402.shown(name) for mode, name in fam.section.modes.items()}


T = TypeVar("T")


async def or_noted(unread: dict[str, str], ref: str, reading: Awaitable[T], fallback: T) -> T:
    """``reading``'s value, or ``fallback`` with the drive's refusal noted under ``ref`` (one aborted read - an
    object the device cannot encode, a value it does not serve - must not take the whole panel with it)."""
    try:
        return await reading
    except DriveBenchError as exc:
        unread[ref] = exc.shown_detail()
        return fallback


async def _diagnostics(session: Session, node: SessionNode, unread: dict[str, str]) -> tuple[list[Bit], int | None]:
    """Digital inputs 0x60FD and error code 0x603F of a generic CiA 402 drive (where it has them)."""
    catalog = catalog_of(node)
    inputs: list[Bit] = []
    if has_ref(catalog, cia402.DIGITAL_INPUTS):
        read = await or_noted(unread, cia402.DIGITAL_INPUTS,
                               reads.read(session, node.node_id, cia402.DIGITAL_INPUTS), None)
        if read is not None:
            word = int(read.raw) if isinstance(read.raw, int) else 0
            inputs = [Bit(bit=bit, name=_(name), set=bool(word >> bit & 1)) for bit, name in cia402.INPUT_BITS.items()]
    code = None
    if has_ref(catalog, cia402.ERROR_CODE):
        value = await or_noted(unread, cia402.ERROR_CODE, reads.read(session, node.node_id, cia402.ERROR_CODE),
                                None)
        code = int(value.raw) & 0xFFFF if value is not None and isinstance(value.raw, int) else None
    return inputs, code


async def read_status(session: Session, node: SessionNode, panel: Panel = SERVICE_PANEL) -> DriveStatus:
    fam = family(node)
    read_at = time.monotonic()
    # Taken before the status word: a note the limit watch writes while the words are read would describe a later
    # state than the word shown with it (a note "the drive clamped" beside a bit 11 read just before it clamped).
    limit_note = soft_limits.note(node) if fam.generic else None
    status_word = await read_word(session, node.node_id, fam.status_ref)
    try:
        control_word: int | None = await read_word(session, node.node_id, fam.control_ref)
    except DriveBenchError:
        control_word = None  # write-only on some devices
    unread: dict[str, str] = {}
    mode = await or_noted(unread, cia402.MODES_OF_OPERATION_DISPLAY, _mode(session, node), None)
    offered = await or_noted(unread, cia402.SUPPORTED_DRIVE_MODES, modes(session, node), section_modes(fam)) if (
        mode is not None or cia402.MODES_OF_OPERATION_DISPLAY in unread) else {}
    scale = await setpoint_scale(session, node, mode)
    inputs, error_code = await _diagnostics(session, node, unread) if fam.generic else ([], None)
    key, label, enabled, fault = describe(fam, status_word)
    guard = guard_for(session)
    if not enabled:
        # Not if a command armed it while the word was read, nor shortly before: an enabling drive passes through
        # states that are not "enabled" on its own cycle (ready -> switched on -> operation enabled), and a read
        # in between must not leave the drive running with nobody holding it.
        guard.release(node.node_id, armed_before=read_at - ARM_SETTLE_S)
    holder = guard.holder(node.node_id)
    section = fam.section
    return DriveStatus(
        node_id=node.node_id, family=fam.key, title=fam.title, note=fam.note, state=key, state_label=label,
        enabled=enabled, fault=fault, status_ref=fam.status_ref, status_word=status_word,
        status_bits=bits(section.status_bits, status_word), control_ref=fam.control_ref, control_word=control_word,
        control_bits=bits(section.control_bits, control_word),
        commands={command.value: command_label(command) for command in section.commands},
        moving_commands=[command.value for command in section.commands if command in fam.moving],
        states=[StateOut(key=box.key, label=cia402.shown(box.label), col=box.col, row=box.row, enabled=box.enabled,
                         fault=box.fault) for box in section.states],
        mode=mode, mode_label=mode_label(fam, mode) if mode is not None else None,
        modes=offered, setpoint_ref=scale.ref,
        setpoint_unit=scale.unit, setpoint_min=scale.minimum, setpoint_max=scale.maximum,
        armed=guard.armed(node.node_id), holder=holder.text() if holder else None,
        you_hold=bool(holder and holder.panel.key == panel.key), panels=guard.panels(node.node_id),
        last_trip=guard.trip_text(node.node_id), generic=fam.generic, inputs=inputs, error_code=error_code,
        error_text=cia402.error_text(error_code) if error_code is not None else None,
        limit_note=limit_note,
        present_fault=fault_words.present_fault(session, node), unread=unread)


# --- commands ------------------------------------------------------------------------------------------------
def _confirmed(confirm: object, node: SessionNode, what: str, values: Values, ctx: WriteContext) -> None:
    """``confirm`` confirmed ``what`` and the ``values`` (nothing to ask when the caller cleared ``ctx``: a move
    that confirmed its mode change)."""
    if not ctx.cleared:
        require_confirmation(confirm, node.node_id, what, values)


def sent(node: SessionNode, ref: str, value: object, unit: str | None = None) -> Values:
    """How a confirmation names the write of ``value`` to ``ref`` (in ``unit``, else the object's own)."""
    try:
        item = catalog_of(node).resolve(ref)
    except UnknownParameter:
        return {ref + (f" [{unit}]" if unit else ""): value}
    return {writes.sent_key(item, unit): value}


def word_values(node: SessionNode, command: str, word: int) -> Values:
    """A command as a confirmation names it: its key and the control word it writes."""
    return {"command": command, **sent(node, family(node).control_ref, f"0x{word:04X}")}


async def write_control_word(session: Session, node: SessionNode, word: int, ctx: WriteContext) -> None:
    """The panel's own write: what moves was confirmed and armed by the caller."""
    await write_word(session, node.node_id, family(node).control_ref, word, ctx.cleared_by_caller())


async def last_control_word(session: Session, node: SessionNode) -> int:
    try:
        return await last_word(session, node.node_id, family(node).control_ref)
    except DriveBenchError:
        return 0  # no control word DriveBench knows


STOPPING = {Command.SHUTDOWN, Command.DISABLE_VOLTAGE, Command.QUICK_STOP, Command.DISABLE_OPERATION}


async def command(session: Session, node: SessionNode, which: Command, *, ctx: WriteContext, confirm: object = None,
                  panel: Panel = SERVICE_PANEL) -> DriveStatus:
    """Send one transition. Stopping commands are open to every panel; the others only to the holder."""
    fam = family(node)
    bits_of = fam.section.commands.get(which)
    if bits_of is None:
        raise InvalidValue(_("{command} is not a command of {control}.").format(command=command_label(which),
                                                                                 control=fam.title))
    guard = guard_for(session)
    if which not in STOPPING:
        guard.check(node.node_id, panel, command_label(which))
    if which in STOPPING:  # a cyclic synchronous stream would send its control word again: it ends first
        live.service(session).stop_node(node.node_id)
    # any station may stop it, and a stop goes before the reads waiting for the node
    ctx = ctx.stopping() if which in STOPPING else ctx
    with session_part.stop_first(session, node.node_id) if which in STOPPING else contextlib.nullcontext():
        last = await last_control_word(session, node)
        word = next_control_word(fam, which, last)
        if which in fam.moving:
            _confirmed(confirm, node, command_label(which), word_values(node, which.value, word), ctx)
        if bits_of.edge is not None and last & bits_of.edge:
            await write_control_word(session, node, last & ~bits_of.edge, ctx)  # a rising edge needs the bit at 0 first
        if which in fam.moving:
            guard.arm(node.node_id, panel)
        await write_control_word(session, node, word, ctx)
    if which in STOPPING:
        guard.release(node.node_id)
    status = await read_status(session, node, panel)
    if which in fam.moving:
        status.command_note = _joined(refusal(fam, which, status),
                                      await fault_words.command_source_note(session, node))
    return status


def refusal(fam: Family, which: Command, status: DriveStatus) -> str | None:
    """Why a moving command left the drive where it was: it is in fault (not after the fault reset itself, whose
    effect the next status shows)."""
    if not status.fault or which is Command.FAULT_RESET:
        return None
    reset = command_label(Command.FAULT_RESET) if Command.FAULT_RESET in fam.section.commands else None
    return fault_words.refusal_note(status.state_label, status.present_fault, reset)


def _joined(*notes: str | None) -> str | None:
    return " ".join(note for note in notes if note) or None


def check_range(value: float, scale: Scale) -> None:
    if (scale.minimum is not None and value < scale.minimum) or (scale.maximum is not None and value > scale.maximum):
        low = "-∞" if scale.minimum is None else f"{scale.minimum:g}"
        high = "∞" if scale.maximum is None else f"{scale.maximum:g}"
        raise OutOfRange(_("Setpoint {value} {unit} is outside {low} ... {high} {unit}.").format(
            value=f"{value:g}", unit=scale.unit, low=low, high=high))


async def set_setpoint(session: Session, node: SessionNode, value: float, *, ctx: WriteContext, confirm: object = None,
                       panel: Panel = SERVICE_PANEL) -> DriveStatus:
    fam = family(node)
    guard = guard_for(session)
    guard.check(node.node_id, panel, _("Setpoint"))
    mode = await _mode(session, node)
    if fam.generic and mode in (1, 6):  # a target alone does not move a CiA 402 drive: it needs the set-point bit
        by = _("a move (POST …/control/move)") if mode == 1 else _("a homing run (POST …/control/home)")
        raise InvalidValue(_("In {mode} mode the drive moves by {by}, not by a setpoint.").format(
            mode=mode_label(fam, mode), by=by))
    spec = _setpoint(fam, mode)
    scale = await setpoint_scale(session, node, mode)
    check_range(value, scale)
    if value != 0:
        _confirmed(confirm, node, _("Setpoint {value} {unit}").format(value=f"{value:g}", unit=scale.unit),
                   sent(node, scale.ref, value, scale.unit), ctx)
        guard.arm(node.node_id, panel)
    done = ctx.cleared_by_caller()  # confirmed and armed above (0 cannot speed it up)
    if scale.raw_per_unit:
        raw = round(value * scale.raw_per_unit) & 0xFFFF
        await writes.write(session, node.node_id, scale.ref, raw, ctx=done, check=False, verify=False)
    else:
        await writes.write(session, node.node_id, scale.ref, value, ctx=done, verify=False)
    if spec.run_bits is not None:  # e.g. CiA 402 velocity mode: run the ramp-function generator (0x7F)
        last = await last_control_word(session, node)
        if last & spec.run_when == spec.run_when and last & spec.run_bits != spec.run_bits:
            await write_control_word(session, node, last | spec.run_bits, ctx)
    if fam.generic and mode in VELOCITY_MODES:
        _watch_limits(session, node, "velocity", value, ctx)
    return await read_status(session, node, panel)


VELOCITY_MODES = (3, 9)
"""CiA 402 profile velocity and cyclic synchronous velocity: the drive need not keep to 0x607D there."""


def _watch_limits(session: Session, node: SessionNode, what: str, velocity: float, ctx: WriteContext) -> None:
    if velocity:
        soft_limits.start(session, node, what, ctx)
    else:
        soft_limits.stop(node)


# --- jog -----------------------------------------------------------------------------------------------------
class JogPlan(BaseModel):
    """How the panel jogs this device: with the device's own jog function, by a setpoint, or (CiA 402) by a
    profile-velocity move."""

    method: str
    """"device" (the control word selects the device's JOG value), "setpoint" (the panel sends a setpoint) or
    "profile_velocity" (mode 3, 0x60FF at a speed the user sets)."""
    value: float
    unit: str
    text: str
    maximum: float | None = None
    """Highest jog speed the user may set (profile-velocity jog: 0x607F max profile velocity)."""


async def jog_plan(session: Session, node: SessionNode) -> JogPlan:
    fam = family(node)
    spec = fam.section.jog
    why = spec.why
    if spec.method == "device" and spec.value_ref is not None and has_ref(catalog_of(node), spec.value_ref):
        if spec.enabled_ref is None or spec.enabled_max is None or \
                await _number(session, node, spec.enabled_ref, 0) <= spec.enabled_max:
            value = await _number(session, node, spec.value_ref, 0)
            return JogPlan(method="device", value=value, unit=spec.unit or "",
                           text=cia402.shown(spec.text).format(value=value, unit=spec.unit, word=fam.control_ref))
        why = spec.disabled_why or why
    if spec.method == "profile_velocity":
        return await profile_velocity_jog(session, node, cia402.shown(spec.text))
    if spec.percent_ref is not None and has_ref(catalog_of(node), spec.percent_ref):
        percent = await _number(session, node, spec.percent_ref, 0)
        reference = await _number(session, node, spec.reference_ref, spec.reference_default)
        value = round(percent / 100 * reference, 1)
        unit = _setpoint(fam, None).unit
        return JogPlan(method="setpoint", value=value, unit=unit,
                       text=cia402.shown(spec.text).format(percent=percent, value=value, unit=unit,
                                                           reference=reference))
    scale = await setpoint_scale(session, node, await _mode(session, node))
    fraction = spec.fraction or 0.1
    value = round((scale.maximum or 100.0) * fraction, 1)
    text = JogSpec().text if spec.percent_ref is not None else spec.text
    return JogPlan(method="setpoint", value=value, unit=scale.unit,
                   text=cia402.shown(text).format(percent=fraction * 100, value=value, unit=scale.unit,
                                                  why=cia402.shown(why)))


async def profile_velocity_jog(session: Session, node: SessionNode, text: str,
                               speed: float | None = None) -> JogPlan:
    """CiA 402 jog: mode 3 at ``speed`` (default a tenth of 0x607F), never above 0x607F."""
    units = await motion_units(session, node)
    top = await _number(session, node, cia402.MAX_PROFILE_VELOCITY, 0.0) or None
    value = speed if speed is not None else round((top or 100.0) / 10, 1)
    if top is not None:
        value = min(abs(value), top)
    return JogPlan(method="profile_velocity", value=abs(value), unit=units.velocity, maximum=top,
                   text=text.format(value=abs(value), unit=units.velocity))


def jog_at(speed: float, unit: str) -> str:
    return _("Jog at {speed} {unit}").format(speed=f"{speed:g}", unit=unit)


def not_enabled(what: str, status: DriveStatus) -> str:
    return _("{what} needs the drive in operation enabled (it is in '{state}').").format(what=what,
                                                                                         state=status.state_label)


async def jog(session: Session, node: SessionNode, direction: int, *, ctx: WriteContext, confirm: object = None,
              panel: Panel = SERVICE_PANEL, speed: float | None = None) -> DriveStatus:
    """Hold-to-run: +1 / -1 runs at the jog value while the keep-alive lasts, 0 stops."""
    if direction not in (-1, 0, 1):
        raise InvalidValue(_("Jog direction is -1, 0 or 1."))
    guard = guard_for(session)
    guard.check(node.node_id, panel, _("Jog"))
    status = await read_status(session, node, panel)
    if direction and not status.enabled:
        raise Conflict(not_enabled(_("Jog"), status))
    plan = await jog_plan(session, node)
    if plan.method == "profile_velocity":
        if speed is not None and speed <= 0:
            raise OutOfRange(_("Jog speed {speed} {unit} must be above 0.").format(speed=f"{speed:g}",
                                                                                    unit=plan.unit))
        if speed is not None and plan.maximum is not None and speed > plan.maximum:
            raise OutOfRange(_("Jog speed {speed} {unit} is above the max profile velocity 0x607F = {top} {unit}.")
                             .format(speed=f"{speed:g}", unit=plan.unit, top=f"{plan.maximum:g}"))
        if direction:
            velocity = sent(node, cia402.TARGET_VELOCITY, direction * (speed or plan.value), plan.unit)
            _confirmed(confirm, node, jog_at(speed or plan.value, plan.unit),
                       {**sent(node, cia402.MODES_OF_OPERATION, 3), **velocity}, ctx)
            guard.arm(node.node_id, panel)
        done = ctx.cleared_by_caller()  # confirmed and armed above; 0 (release) stops it
        if direction and status.mode != 3:
            await writes.write(session, node.node_id, cia402.MODES_OF_OPERATION, 3, ctx=done, verify=False)
        value = direction * (speed or plan.value)
        await writes.write(session, node.node_id, cia402.TARGET_VELOCITY, value, ctx=done, verify=False)
        _watch_limits(session, node, "jog", value, ctx)
        return await read_status(session, node, panel)
    if plan.method == "setpoint":
        return await set_setpoint(session, node, direction * plan.value, ctx=ctx, confirm=confirm, panel=panel)
    spec = family(node).section.jog
    word = await last_control_word(session, node) & ~spec.select_mask
    if direction:
        word |= spec.forward if direction > 0 else spec.reverse
        jogged = sent(node, spec.value_ref, plan.value, plan.unit) if spec.value_ref else {}
        _confirmed(confirm, node, jog_at(plan.value, plan.unit),
                   {**word_values(node, "jog_forward" if direction > 0 else "jog_reverse", word), **jogged}, ctx)
        guard.arm(node.node_id, panel)
    await write_control_word(session, node, word, ctx)
    return await read_status(session, node, panel)


MODE_SETTLE_S = 1.0
"""How long a drive may take to show a new mode in 0x6061."""


async def set_mode(session: Session, node: SessionNode, mode: int, *, ctx: WriteContext, confirm: object = None,
                   panel: Panel = SERVICE_PANEL) -> DriveStatus:
    fam = family(node)
    if fam.section.state_machine != "cia402" or not has_ref(catalog_of(node), cia402.MODES_OF_OPERATION):
        raise InvalidValue(_("{device} has no modes of operation (0x6060).").format(device=node.device_name))
    if mode not in await modes(session, node):
        unknown = cia402.shown(fam.section.modes_help) if fam.section.modes_help else _("Mode {mode} is not supported.")
        raise InvalidValue(unknown.format(mode=mode))
    guard_for(session).check(node.node_id, panel, _("Changing the mode of operation"))
    status = await read_status(session, node, panel)
    if status.enabled:
        _confirmed(confirm, node, _("Changing the mode of operation while the drive is enabled"),
                   sent(node, cia402.MODES_OF_OPERATION, mode), ctx)
    # confirmed above while enabled; a disabled drive does not move when its mode changes
    await writes.write(session, node.node_id, cia402.MODES_OF_OPERATION, mode, ctx=ctx.cleared_by_caller(),
                           verify=False)
    deadline = time.monotonic() + MODE_SETTLE_S
    while (status := await read_status(session, node, panel)).mode != mode and time.monotonic() < deadline:
        await asyncio.sleep(0.02)
    if status.mode != mode:
        refused = (cia402.shown(fam.section.mode_refused) if fam.section.mode_refused else
                   _("0x6061 shows {shown} after writing 0x6060 = {mode}."))
        raise Conflict(refused.format(shown=status.mode, mode=mode))
    return status
