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

The guard itself (arming, holders, keep-alive deadlines, quick stop) is :mod:`drivebench.services.drive_guard`.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

from pydantic import BaseModel

from drivebench.device.catalog import Catalog
from drivebench.errors import Conflict, DriveBenchError, InvalidValue, OutOfRange, UnknownParameter
from drivebench.services import node_lease, parameters
from drivebench.services.drive_guard import (
    ARM_SETTLE_S,
    SERVICE_PANEL,
    Panel,
    guard_for,
    last_word,
    read_word,
    require_confirmation,
    write_word,
)
from drivebench.services.drive_words import (
    CIA402,
    COMMAND_LABELS,
    EMF,
    EMF_AIF,
    L8400,
    MOVING,
    Command,
    Family,
    family_of,
    next_control_word,
    state_label,
)
from drivebench.services.sessions import Session, SessionNode

# the rest of the guard's surface, re-exported for this module's callers (web api/ws/pages, tests)
from drivebench.services.drive_guard import KEEPALIVE_TIMEOUT_S as KEEPALIVE_TIMEOUT_S  # isort: skip
from drivebench.services.drive_guard import Guard as Guard  # isort: skip
from drivebench.services.drive_guard import Holder as Holder  # isort: skip
from drivebench.services.drive_guard import panel_of as panel_of  # isort: skip

MODES = {2: "Velocity mode", 4: "Profile torque mode"}  # MICROMASTER table 3-20 (profile torque: MM440 only)
CW_RUN_RFG = 0x70  # MICROMASTER velocity mode: RFG enable, RFG start, setpoint enable


# --- setpoint and actual values --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scale:
    """User value = raw / raw_per_unit (a Lenze process-data word) or the profile's own scaling (raw_per_unit 0)."""

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


def _catalog(node: SessionNode) -> Catalog:
    if node.catalog is None:
        raise InvalidValue(f"Node {node.node_id} has no device profile: the control panel needs one.")
    return node.catalog


def family(node: SessionNode) -> Family:
    found = family_of(node.catalog)
    if found is None:
        raise InvalidValue(f"{node.device_name} has no device control word DriveBench knows (CiA 402 0x6040/0x6041, "
                           "Lenze C0135/C0150, AIF word 1 or 8400 CAN1_IN/CAN1_OUT).")
    return found


def _is_8200(catalog: Catalog) -> bool:
    return has_ref(catalog, "C0001")


async def setpoint_scale(session: Session, node: SessionNode, mode: int | None) -> Scale:
    fam, catalog = family(node), _catalog(node)
    if fam is CIA402:
        if mode == 4:
            return Scale("0x6071", "‰", minimum=-1000, maximum=1000)
        top = 1500.0
        if has_ref(catalog, "0x6046.2"):
            top = float((await parameters.read(session, node.node_id, "0x6046.2")).value or top)
        return Scale("0x6042", "rpm", minimum=-top, maximum=top)
    if fam in (EMF, EMF_AIF):
        if _is_8200(catalog):  # 24000 = 480 Hz (EMF2178IB ch. 9.3.1.1)
            return Scale("C1822/2", "Hz", 50.0, -480, 480)
        return Scale("C1822/2", "%", 16383 / 100, -100, 100)  # 93XX: 16383 = 100 %
    reference = 1500.0
    if has_ref(catalog, "C00011"):
        reference = float((await parameters.read(session, node.node_id, "C00011")).value or reference)
    return Scale("C00866/2", "rpm", 0x4000 / reference, -2 * reference, 2 * reference)  # 0x4000 = C00011


def actual_refs(node: SessionNode) -> list[tuple[str, str, Scale | None]]:
    """(label, ref, word scale or None for the profile's own scaling) of the actual values this device has."""
    fam, catalog = family(node), _catalog(node)
    wanted: list[tuple[str, str, Scale | None]]
    if fam is CIA402:
        wanted = [("Speed", "0x6044", None), ("Output frequency", "r0021", None), ("Current", "r0027", None),
                  ("DC-bus voltage", "r0026", None), ("Torque", "r0080", None), ("Torque", "0x6077", None),
                  ("Heat-sink temperature", "r0037", None)]
    elif fam in (EMF, EMF_AIF):
        word = Scale("C1823/2", "Hz", 50.0) if _is_8200(catalog) else Scale("C1823/2", "%", 16383 / 100)
        wanted = [("Speed (AIF-OUT.W1)", "C1823/2", word), ("Current", "C0054", None),
                  ("DC-bus voltage", "C0053", None), ("Torque", "C0056", None),
                  ("Heat-sink temperature", "C0061", None)]
    else:
        wanted = [("Speed (CAN1_OUT word 2)", "C00868/2", None), ("Current", "C00054", None),
                  ("DC-bus voltage", "C00053", None), ("Torque", "C00056", None),
                  ("Heat-sink temperature", "C00061", None)]
    return [entry for entry in wanted if has_ref(catalog, entry[1])]


ACTUAL_KINDS = ("Speed", "Current", "DC-bus voltage", "Torque", "Heat-sink temperature")


def missing_actuals(node: SessionNode) -> list[str]:
    """The kinds of actual value the panel plots elsewhere that this device's profile (and its manual) lacks."""
    present = {label.split(" (")[0] for label, _, _ in actual_refs(node)}
    return [kind for kind in ACTUAL_KINDS if kind not in present]


def missing_why(node: SessionNode) -> str:
    """Why the values :func:`missing_actuals` names are not there: which manual was searched for what."""
    fam, catalog = family(node), _catalog(node)
    if fam is CIA402:
        return ("neither the MICROMASTER CANopen manual nor the MICROMASTER 440 parameter list entries taken over "
                "(r0026, r0027, r0031, r0037) give it")
    if fam in (EMF, EMF_AIF) and _is_8200(catalog):
        return ("no actual-torque code: the EMF2178IB manual names only C0061, and only C0053 (DC bus) and C0054 "
                "(motor current) were taken over from the 8200 vector code table")
    if fam in (EMF, EMF_AIF):
        return ("the EMF2178IB manual names only C0061 (heat-sink temperature) among the actual values; the 93XX "
                "code table is not among the seed manuals")
    return ("C00056 (torque) is named in the 8400 BaseLine C parameter list without unit or scaling and is not "
            "assumed for the motec")


def actual_source(node: SessionNode, ref: str, scale: Scale | None = None) -> str:
    """Where a plotted value comes from: the object it is read from, its coding, and the manual that names it."""
    catalog = _catalog(node)
    item = catalog.resolve(ref)
    coding = item.entry.data_type.name
    if scale is not None and scale.raw_per_unit:
        coding += f", {scale.unit} = raw / {scale.raw_per_unit:g}"
    elif item.entry.factor != 1:
        coding += f", value = raw / {item.entry.factor:g}"
    text = item.entry.description or ""
    if text.startswith("Source: "):
        manual = text[len("Source: "):].split(". ")[0].rstrip(".")
    else:
        manual = catalog.profile.source.split(", ")[0] if catalog.profile.source else "this device's profile"
    return f"{ref} = 0x{item.index:04X}.{item.subindex} ({coding}); {manual}"


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
    speed_scale: Scale | None = None
    if family(node) is L8400:
        speed_scale = await setpoint_scale(session, node, None)
    for label, ref, scale in actual_refs(node):
        source = actual_source(node, ref, speed_scale if ref == "C00868/2" else scale)
        try:
            value = await parameters.read(session, node.node_id, ref)
        except DriveBenchError as exc:
            out.append(ActualValue(label=label, ref=ref, value=None, unit=None, error=str(exc), source=source))
            continue
        if ref == "C00868/2" and speed_scale is not None and isinstance(value.raw, int):
            out.append(ActualValue(label=label, ref=ref, unit="rpm", source=source,
                                   value=round(_signed16(value.raw) / speed_scale.raw_per_unit, 1)))
        elif scale is not None and isinstance(value.raw, int):
            out.append(ActualValue(label=label, ref=ref, unit=scale.unit, source=source,
                                   value=round(_signed16(value.raw & 0xFFFF) / scale.raw_per_unit, 2)))
        else:
            number = round(value.value, 3) if isinstance(value.value, (int, float)) else None  # REAL32 noise
            out.append(ActualValue(label=label, ref=ref, value=number, unit=value.unit, source=source))
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


def bits(names: dict[int, str], word: int | None) -> list[Bit]:
    return [Bit(bit=bit, name=names.get(bit, f"Bit {bit}"), set=bool(word is not None and word >> bit & 1))
            for bit in range(16)]


def describe(fam: Family, status_word: int) -> tuple[str, str, bool, bool]:
    """(state key, label, enabled?, fault?) for a status word."""
    key = fam.state_of(status_word)
    box = fam.state_box(key)
    return key, state_label(fam, key), bool(box and box.enabled), bool(box and box.fault)


async def _mode(session: Session, node: SessionNode) -> int | None:
    if family(node) is not CIA402 or not has_ref(_catalog(node), "0x6061"):
        return None
    raw = (await parameters.read(session, node.node_id, "0x6061")).raw
    return int(raw) if isinstance(raw, int) else None


async def read_status(session: Session, node: SessionNode, panel: Panel = SERVICE_PANEL) -> DriveStatus:
    fam = family(node)
    read_at = time.monotonic()
    status_word = await read_word(session, node.node_id, fam.status_ref)
    try:
        control_word: int | None = await read_word(session, node.node_id, fam.control_ref)
    except DriveBenchError:
        control_word = None  # write-only on some devices
    mode = await _mode(session, node)
    scale = await setpoint_scale(session, node, mode)
    key, label, enabled, fault = describe(fam, status_word)
    guard = guard_for(session)
    if not enabled:
        # Not if a command armed it while the word was read, nor shortly before: an enabling drive passes through
        # states that are not "enabled" on its own cycle (ready -> switched on -> operation enabled), and a read
        # in between must not leave the drive running with nobody holding it.
        guard.release(node.node_id, armed_before=read_at - ARM_SETTLE_S)
    holder = guard.holder(node.node_id)
    return DriveStatus(
        node_id=node.node_id, family=fam.key, title=fam.title, note=fam.note, state=key, state_label=label,
        enabled=enabled, fault=fault, status_ref=fam.status_ref, status_word=status_word,
        status_bits=bits(fam.status_bits, status_word), control_ref=fam.control_ref, control_word=control_word,
        control_bits=bits(fam.control_bits, control_word),
        commands={command.value: COMMAND_LABELS[command] for command in fam.commands},
        moving_commands=[command.value for command in fam.commands if command in MOVING],
        states=[StateOut(key=box.key, label=box.label, col=box.col, row=box.row, enabled=box.enabled, fault=box.fault)
                for box in fam.states],
        mode=mode, mode_label=MODES.get(mode) if mode is not None else None,
        modes=MODES if mode is not None else {}, setpoint_ref=scale.ref, setpoint_unit=scale.unit,
        setpoint_min=scale.minimum, setpoint_max=scale.maximum, armed=guard.armed(node.node_id),
        holder=holder.text() if holder else None, you_hold=bool(holder and holder.panel.key == panel.key),
        panels=guard.panels(node.node_id),
        last_trip=guard.trips.get(node.node_id))


# --- commands ------------------------------------------------------------------------------------------------
def _confirmed(confirm: object, node: SessionNode, what: str) -> None:
    require_confirmation(confirm, node.node_id, what)


async def write_control_word(session: Session, node: SessionNode, word: int) -> None:
    await write_word(session, node.node_id, family(node).control_ref, word)


async def _last_control_word(session: Session, node: SessionNode) -> int:
    try:
        return await last_word(session, node.node_id, family(node).control_ref)
    except DriveBenchError:
        return 0  # no control word DriveBench knows


STOPPING = {Command.SHUTDOWN, Command.DISABLE_VOLTAGE, Command.QUICK_STOP, Command.DISABLE_OPERATION}


async def command(session: Session, node: SessionNode, which: Command, *, confirm: object = None,
                  panel: Panel = SERVICE_PANEL) -> DriveStatus:
    """Send one transition. Stopping commands are open to every panel; the others only to the holder."""
    fam = family(node)
    if which not in fam.commands:
        raise InvalidValue(f"{COMMAND_LABELS[which]} is not a command of {fam.title}.")
    guard = guard_for(session)
    if which not in STOPPING:
        guard.check(node.node_id, panel, COMMAND_LABELS[which])
    if which in MOVING:
        _confirmed(confirm, node, COMMAND_LABELS[which])
    with node_lease.stopping() if which in STOPPING else contextlib.nullcontext():  # any station may stop it
        last = await _last_control_word(session, node)
        word = next_control_word(fam, which, last)
        edge = fam.edge_bits.get(which)
        if edge is not None and last & edge:
            await write_control_word(session, node, last & ~edge)  # a rising edge needs the bit at 0 first
        if which in MOVING:
            guard.arm(node.node_id, panel)
        await write_control_word(session, node, word)
    if which in STOPPING:
        guard.release(node.node_id)
    return await read_status(session, node, panel)


async def set_setpoint(session: Session, node: SessionNode, value: float, *, confirm: object = None,
                       panel: Panel = SERVICE_PANEL) -> DriveStatus:
    fam = family(node)
    guard = guard_for(session)
    guard.check(node.node_id, panel, "Setpoint")
    scale = await setpoint_scale(session, node, await _mode(session, node))
    if (scale.minimum is not None and value < scale.minimum) or (scale.maximum is not None and value > scale.maximum):
        raise OutOfRange(f"Setpoint {value:g} {scale.unit} is outside {scale.minimum:g} ... {scale.maximum:g} "
                         f"{scale.unit}.")
    if value != 0:
        _confirmed(confirm, node, f"Setpoint {value:g} {scale.unit}")
        guard.arm(node.node_id, panel)
    if scale.raw_per_unit:
        raw = round(value * scale.raw_per_unit) & 0xFFFF
        await parameters.write(session, node.node_id, scale.ref, raw, check=False, verify=False)
    else:
        await parameters.write(session, node.node_id, scale.ref, value, verify=False)
    if fam is CIA402 and scale.ref == "0x6042":
        last = await _last_control_word(session, node)
        if last & 0x0F == 0x0F and last & CW_RUN_RFG != CW_RUN_RFG:  # velocity mode: run the ramp (0x7F)
            await write_control_word(session, node, last | CW_RUN_RFG)
    return await read_status(session, node, panel)


# --- jog -----------------------------------------------------------------------------------------------------
EMF_JOG1 = 0x0001  # AIF-CTRL bits 1/0 = 01: NSET1-JOG1 (C0037) active (EMF2178IB ch. 9.3.1.1, C0007 <= 51)
EMF_JOG_SELECT = 0x0003
EMF_CCW = 0x0004  # bit 2: DCTRL1-CW/CCW


class JogPlan(BaseModel):
    """How the panel jogs this device: with the device's own jog function or by a setpoint."""

    method: str
    """"device" (the control word selects the device's JOG value) or "setpoint" (the panel sends a setpoint)."""
    value: float
    unit: str
    text: str


async def _number(session: Session, node: SessionNode, ref: str, default: float) -> float:
    if not has_ref(_catalog(node), ref):
        return default
    value = (await parameters.read(session, node.node_id, ref)).value
    return float(value) if isinstance(value, (int, float)) else default


async def jog_plan(session: Session, node: SessionNode) -> JogPlan:
    fam, catalog = family(node), _catalog(node)
    scale = await setpoint_scale(session, node, await _mode(session, node))
    why = "this device's manual gives the panel no jog function"
    if fam is EMF and _is_8200(catalog) and has_ref(catalog, "C0037"):
        if await _number(session, node, "C0007", 0) <= 51:
            hz = await _number(session, node, "C0037", 0)
            return JogPlan(method="device", value=hz, unit="Hz",
                           text=f"Device jog: {fam.control_ref} bits 1/0 = 01 select NSET1-JOG1 (C0037 = {hz:g} Hz), "
                                "bit 2 (DCTRL1-CW/CCW) turns it round (EMF2178IB ch. 9.3.1.1).")
        why = "with C0007 > 51 control bits 0/1 are freely configurable, not the JOG selection"
    elif fam is L8400 and has_ref(catalog, "C00039/1"):
        percent = await _number(session, node, "C00039/1", 0)
        rpm = round(percent / 100 * await _number(session, node, "C00011", 1500), 1)
        return JogPlan(method="setpoint", value=rpm, unit="rpm",
                       text=f"Setpoint jog at C00039/1 Fixed setpoint-JOG1 = {percent:g} % of C00011 = {rpm:g} rpm, "
                            "sent as the speed setpoint (CAN1_IN word 2): the 8400 CANopen manual names no "
                            "control-word bit that selects JOG1.")
    elif fam is CIA402:
        why = "the MICROMASTER CANopen manual gives no jog (control bit 8 is 'Halt, not used in CAN')"
    elif fam is EMF_AIF:
        why = "the EMF2178IB manual names NSET-JOG*1/*2 (control bits 0/1) for the 93XX but not its JOG values"
    top = scale.maximum or 100.0
    value = round(top / 10, 1)
    return JogPlan(method="setpoint", value=value, unit=scale.unit,
                   text=f"Setpoint jog at 10 % of the range ({value:g} {scale.unit}): {why}.")


async def jog(session: Session, node: SessionNode, direction: int, *, confirm: object = None,
              panel: Panel = SERVICE_PANEL) -> DriveStatus:
    """Hold-to-run: +1 / -1 runs at the jog value while the keep-alive lasts, 0 stops."""
    if direction not in (-1, 0, 1):
        raise InvalidValue("Jog direction is -1, 0 or 1.")
    guard = guard_for(session)
    guard.check(node.node_id, panel, "Jog")
    status = await read_status(session, node, panel)
    if direction and not status.enabled:
        raise Conflict(f"Jog needs the drive in operation enabled (it is in '{status.state_label}').")
    plan = await jog_plan(session, node)
    if plan.method == "setpoint":
        return await set_setpoint(session, node, direction * plan.value, confirm=confirm, panel=panel)
    if direction:
        _confirmed(confirm, node, f"Jog at {plan.value:g} {plan.unit}")
        guard.arm(node.node_id, panel)
    word = await _last_control_word(session, node) & ~(EMF_JOG_SELECT | EMF_CCW)
    if direction:
        word |= EMF_JOG1 | (EMF_CCW if direction < 0 else 0)
    await write_control_word(session, node, word)
    return await read_status(session, node, panel)


async def set_mode(session: Session, node: SessionNode, mode: int, *, confirm: object = None,
                   panel: Panel = SERVICE_PANEL) -> DriveStatus:
    if family(node) is not CIA402 or not has_ref(_catalog(node), "0x6060"):
        raise InvalidValue(f"{node.device_name} has no modes of operation (0x6060).")
    if mode not in MODES:
        raise InvalidValue(f"Mode {mode} is not supported: the MICROMASTER knows 2 (velocity) and 4 (profile torque).")
    guard_for(session).check(node.node_id, panel, "Changing the mode of operation")
    status = await read_status(session, node, panel)
    if status.enabled:
        _confirmed(confirm, node, "Changing the mode of operation while the drive is enabled")
    await parameters.write(session, node.node_id, "0x6060", mode, verify=False)
    status = await read_status(session, node, panel)
    if status.mode != mode:
        raise Conflict(f"0x6061 shows {status.mode} after writing 0x6060 = {mode}: the MICROMASTER takes 0x6060 only "
                       "once P1501 = r2091.12 (0x082B000C), see the commissioning wizard step 5.")
    return status
