"""CiA 402-2 motion of a drive without a vendor control section: profile position moves and homing.

* Profile position (mode 1): target 0x607A, profile velocity 0x6081; control word bit 4 *new set-point* (rising
  edge), bit 5 *change set immediately*, bit 6 *relative*; the drive answers with status bit 12 *set-point
  acknowledge*, then the panel takes bit 4 back; status bit 10 *target reached* ends the move.
* Homing (mode 6): method 0x6098, speeds 0x6099 (1: search for switch, 2: search for zero), acceleration 0x609A,
  home offset 0x607C; control word bit 4 *homing operation start* stays set while homing runs; status bit 12
  *homing attained*, bit 13 *homing error*. The methods offered are those the drive lists in 0x60E3 (supported
  homing methods) where it has that object, else every CiA 402 method.

The interlocks are drive_control's: only the panel holding the drive moves it, a move is confirmed with the node
id and arms the keep-alive guard.
"""

from __future__ import annotations

import asyncio
import time

from pydantic import BaseModel

from drivebench.device.drive import cia402
from drivebench.errors import Conflict, DriveBenchError, InvalidValue, OutOfRange
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control import drive_control, soft_limits
from drivebench.services.control.drive_control import SERVICE_PANEL, DriveStatus, Panel, guard_for, has_ref
from drivebench.services.control.drive_units import motion_units
from drivebench.services.params import reads, writes
from drivebench.services.params.write_context import WriteContext
from drivebench.services.pdos import process_data as live

NEW_SET_POINT, CHANGE_IMMEDIATELY, RELATIVE = 0x0010, 0x0020, 0x0040
MODE_BITS = NEW_SET_POINT | CHANGE_IMMEDIATELY | RELATIVE | 0x0100  # and halt
SET_POINT_ACKNOWLEDGE = 0x1000
ACK_TIMEOUT_S = 1.0
QUICK_STOP_OPTIONS = {
    0: N_("disable drive function"), 1: N_("slow down on slow-down ramp, then switch on disabled"),
    2: N_("slow down on quick-stop ramp, then switch on disabled"),
    3: N_("slow down on current limit, then switch on disabled"),
    4: N_("slow down on voltage limit, then switch on disabled"),
    5: N_("slow down on slow-down ramp and stay in quick stop active"),
    6: N_("slow down on quick-stop ramp and stay in quick stop active"),
    7: N_("slow down on current limit and stay in quick stop active"),
    8: N_("slow down on voltage limit and stay in quick stop active"),
}


class Setting(BaseModel):
    ref: str
    label: str
    value: float | None
    unit: str | None


class MotionInfo(BaseModel):
    position_unit: str
    velocity_unit: str
    units_from: str
    quick_stop_option: str | None
    settings: list[Setting]
    """Profile and homing parameters as the drive holds them (0x6081, 0x6083, 0x6084, 0x6085, 0x6099, 0x609A,
    0x607C, 0x607D, 0x607F, 0x60C2)."""
    homing_methods: dict[int, str]
    homing_method: int | None


SETTINGS = [(cia402.PROFILE_VELOCITY, N_("Profile velocity"), "velocity"),
            (cia402.PROFILE_ACCELERATION, N_("Profile acceleration"), "acceleration"),
            (cia402.PROFILE_DECELERATION, N_("Profile deceleration"), "acceleration"),
            (cia402.QUICK_STOP_DECELERATION, N_("Quick stop deceleration"), "acceleration"),
            (cia402.SPEED_SEARCH_FOR_SWITCH, N_("Homing speed: search for switch"), "velocity"),
            (cia402.SPEED_SEARCH_FOR_ZERO, N_("Homing speed: search for zero"), "velocity"),
            (cia402.HOMING_ACCELERATION, N_("Homing acceleration"), "acceleration"),
            (cia402.HOME_OFFSET, N_("Home offset"), "position"),
            (cia402.MIN_POSITION_LIMIT, N_("Software position limit: min"), "position"),
            (cia402.MAX_POSITION_LIMIT, N_("Software position limit: max"), "position"),
            (cia402.MAX_PROFILE_VELOCITY, N_("Max profile velocity"), "velocity"),
            (cia402.INTERPOLATION_PERIOD_VALUE, N_("Interpolation time period value"), None),
            (cia402.INTERPOLATION_PERIOD_INDEX, N_("Interpolation time index (period = value x 10^index s)"), None)]


async def _read(session: Session, node: SessionNode, ref: str) -> float | None:
    value = (await reads.read(session, node.node_id, ref)).value
    return float(value) if isinstance(value, (int, float)) else None


async def info(session: Session, node: SessionNode) -> MotionInfo:
    catalog = drive_control.catalog_of(node)
    if not drive_control.family(node).generic:
        raise InvalidValue(_("{device} is driven by its profile's own control section, not by the standard CiA 402 "
                             "motion panel.").format(device=node.device_name))
    units = await motion_units(session, node)
    unit_of = {"position": units.position, "velocity": units.velocity, "acceleration": f"{units.velocity}/s"}
    settings = [Setting(ref=ref, label=_(label), value=await _read(session, node, ref),
                        unit=unit_of.get(kind or "") or catalog.resolve(ref).entry.unit)
                for ref, label, kind in SETTINGS if has_ref(catalog, ref)]
    option = None
    if has_ref(catalog, cia402.QUICK_STOP_OPTION_CODE):
        code = await _read(session, node, cia402.QUICK_STOP_OPTION_CODE)
        if code is not None:
            named = QUICK_STOP_OPTIONS.get(int(code))
            option = f"{code:g}: " + (_(named) if named else _("manufacturer-specific") if code < 0 else _("reserved"))
    homing = has_ref(catalog, cia402.HOMING_METHOD)
    method = await _read(session, node, cia402.HOMING_METHOD) if homing else None
    return MotionInfo(position_unit=units.position, velocity_unit=units.velocity, units_from=units.how,
                      quick_stop_option=option, settings=settings,
                      homing_methods=await homing_methods(session, node) if homing else {},
                      homing_method=int(method) if method is not None else None)


async def homing_methods(session: Session, node: SessionNode) -> dict[int, str]:
    """The methods the drive lists in 0x60E3 (read once per node: read-only), else every CiA 402 method; named in
    the reader's language."""
    cached: list[int] | None = getattr(node, "_homing_methods", None)  # kept on the node, as its units
    if cached is None:
        catalog = drive_control.catalog_of(node)
        cached = list(cia402.HOMING_METHODS)
        methods = cia402.SUPPORTED_HOMING_METHODS
        if has_ref(catalog, cia402.sub(methods, 1)):
            count = int(await _read(session, node, cia402.sub(methods, 0)) or 0)
            refs = [cia402.sub(methods, number) for number in range(1, count + 1)
                    if has_ref(catalog, cia402.sub(methods, number))]
            cached = [found.value for found in await reads.read_many(session, node.node_id, refs)
                      if not isinstance(found, DriveBenchError) and isinstance(found.value, int)]
        object.__setattr__(node, "_homing_methods", cached)
    return {method: cia402.homing_label(method) for method in cached}


async def _enabled(session: Session, node: SessionNode, panel: Panel, what: str) -> DriveStatus:
    guard_for(session).check(node.node_id, panel, what)
    status = await drive_control.read_status(session, node, panel)
    if not status.generic:
        raise InvalidValue(_("{device} is not driven by the standard CiA 402 panel.").format(device=node.device_name))
    if not status.enabled:
        raise Conflict(drive_control.not_enabled(what, status))
    return status


async def _mode(session: Session, node: SessionNode, status: DriveStatus, mode: int, panel: Panel,
                ctx: WriteContext) -> None:
    if status.mode != mode:
        if mode not in status.modes:
            raise InvalidValue(_("{device} does not support {mode} mode.").format(device=node.device_name,
                                                                                   mode=cia402.mode_label(mode)))
        # the move, homing run or stream that needs it was confirmed with this mode
        await drive_control.set_mode(session, node, mode, ctx=ctx.cleared_by_caller(), panel=panel)


async def _edge(session: Session, node: SessionNode, base: int, ctx: WriteContext, *, hold: bool) -> None:
    """Bit 4 from 0 to 1 on top of ``base``; unless ``hold``, back to 0 once the drive acknowledged it."""
    await drive_control.write_control_word(session, node, base, ctx)
    await drive_control.write_control_word(session, node, base | NEW_SET_POINT, ctx)
    if hold:
        return
    deadline = time.monotonic() + ACK_TIMEOUT_S
    while True:
        word = (await reads.read(session, node.node_id, cia402.STATUS_WORD)).raw
        if isinstance(word, int) and word & SET_POINT_ACKNOWLEDGE:
            break
        if time.monotonic() > deadline:
            raise Conflict(_("The drive did not acknowledge the new set-point (status word bit 12) within {seconds} s.")
                           .format(seconds=f"{ACK_TIMEOUT_S:g}"))
        await asyncio.sleep(0.01)
    await drive_control.write_control_word(session, node, base, ctx)


async def move(session: Session, node: SessionNode, target: float, *, relative: bool = False,
               immediate: bool = True, velocity: float | None = None, ctx: WriteContext, confirm: object = None,
               panel: Panel = SERVICE_PANEL) -> DriveStatus:
    """A profile-position move to ``target`` (position units), at ``velocity`` (0x6081) when given."""
    status = await _enabled(session, node, panel, _("A profile-position move"))
    units = await motion_units(session, node)
    if velocity is not None:
        top = (await _read(session, node, cia402.MAX_PROFILE_VELOCITY)
               if has_ref(drive_control.catalog_of(node), cia402.MAX_PROFILE_VELOCITY) else None)
        if velocity <= 0 or (top and velocity > top):
            raise OutOfRange(_("Profile velocity {velocity} {unit} is outside 0 ... {top} {unit} (0x607F max profile "
                               "velocity).").format(velocity=f"{velocity:g}", unit=units.velocity,
                                                    top=f"{top:g}" if top else "∞"))
    if not relative:
        scale = await drive_control.setpoint_scale(session, node, 1)
        if (scale.minimum is not None and target < scale.minimum) or \
                (scale.maximum is not None and target > scale.maximum):
            raise OutOfRange(_("Target {target} {unit} is outside the software position limits 0x607D {low} ... "
                               "{high} {unit}.").format(target=f"{target:g}", unit=units.position,
                                                        low=f"{scale.minimum:g}", high=f"{scale.maximum:g}"))
    else:
        await soft_limits.check_relative(session, node, target)
    values = {**drive_control.sent(node, cia402.MODES_OF_OPERATION, 1),
              **drive_control.sent(node, cia402.TARGET_POSITION, target, units.position),
              "relative": relative, "immediate": immediate}
    if velocity is not None:
        values.update(drive_control.sent(node, cia402.PROFILE_VELOCITY, velocity, units.velocity))
    drive_control.require_confirmation(confirm, node.node_id, _("Move to {target} {unit}").format(
        target=f"{target:g}", unit=units.position), values)
    guard_for(session).arm(node.node_id, panel)
    await _mode(session, node, status, 1, panel, ctx)
    done = ctx.cleared_by_caller()  # confirmed and armed above
    if velocity is not None:
        await writes.write(session, node.node_id, cia402.PROFILE_VELOCITY, velocity, ctx=done, verify=False)
    await writes.write(session, node.node_id, cia402.TARGET_POSITION, target, ctx=done, verify=False)
    base = await drive_control.last_control_word(session, node) & ~MODE_BITS
    base |= (CHANGE_IMMEDIATELY if immediate else 0) | (RELATIVE if relative else 0)
    await _edge(session, node, base, ctx, hold=False)
    if relative:
        soft_limits.start(session, node, "move", ctx)
    return await drive_control.read_status(session, node, panel)


async def home(session: Session, node: SessionNode, method: int, *, ctx: WriteContext, confirm: object = None,
               panel: Panel = SERVICE_PANEL) -> DriveStatus:
    """Homing (mode 6) with ``method`` (0x6098); bit 4 stays set until the next command."""
    supported = await homing_methods(session, node)
    if method not in supported:
        among = (_("the supported homing methods 0x60E3 of {device} ({methods})").format(
            device=node.device_name, methods=", ".join(map(str, supported)))
                 if has_ref(drive_control.catalog_of(node), cia402.sub(cia402.SUPPORTED_HOMING_METHODS, 1)) else
                 _("the CiA 402 methods (1 ... 14, 17 ... 30, 33 ... 35, 37; the drive lists no others in 0x60E3)"))
        raise InvalidValue(_("Homing method {method} ({name}) is not among {among}.").format(
            method=method, name=cia402.homing_label(method), among=among))
    status = await _enabled(session, node, panel, _("Homing"))
    drive_control.require_confirmation(confirm, node.node_id, _("Homing with method {method} ({name})").format(
        method=method, name=cia402.homing_label(method)),
        {**drive_control.sent(node, cia402.MODES_OF_OPERATION, 6),
         **drive_control.sent(node, cia402.HOMING_METHOD, method)})
    guard_for(session).arm(node.node_id, panel)
    await _mode(session, node, status, 6, panel, ctx)
    # confirmed and armed above
    await writes.write(session, node.node_id, cia402.HOMING_METHOD, method, ctx=ctx.cleared_by_caller(),
                           verify=False)
    base = await drive_control.last_control_word(session, node) & ~MODE_BITS
    await _edge(session, node, base, ctx, hold=True)
    return await drive_control.read_status(session, node, panel)


# --- interpolated position (7) and cyclic synchronous modes (8/9/10): the setpoint travels in an RPDO every SYNC --
ENABLE_IP_MODE = NEW_SET_POINT
"""Interpolated position: control word bit 4 *enable ip mode*; the drive answers with status bit 12 *ip mode
active* and follows the interpolation data record 0x60C1.1, linearly over each interpolation period (0x60C2)."""


class CyclicStream(BaseModel):
    mode: int
    rpdo: int
    cob_id: int
    period_ms: int
    data: str
    """The RPDO as sent every cycle (control word and setpoint), hex."""


async def _cycle_ms(session: Session, node: SessionNode) -> int:
    """The interpolation time period 0x60C2 (value x 10^index s) in ms, 10 ms when the drive has none."""
    catalog = drive_control.catalog_of(node)
    if not has_ref(catalog, cia402.INTERPOLATION_PERIOD_VALUE):
        return 10
    value = await _read(session, node, cia402.INTERPOLATION_PERIOD_VALUE) or 10
    index = (await _read(session, node, cia402.INTERPOLATION_PERIOD_INDEX)
             if has_ref(catalog, cia402.INTERPOLATION_PERIOD_INDEX) else -3)
    return max(1, round(value * 10 ** (index if index is not None else -3) * 1000))


async def stream(session: Session, node: SessionNode, value: float, *, confirm: object = None,
                 panel: Panel = SERVICE_PANEL) -> CyclicStream:
    """Interpolated position or cyclic synchronous position / velocity / torque: SYNC at the drive's interpolation
    period (0x60C2) and an RPDO mapping the control word and the mode's target (interpolated position: the data
    record 0x60C1.1, with bit 4 *enable ip mode* in the control word), sent every cycle while the panel holds the
    drive."""
    status = await _enabled(session, node, panel, _("A cyclic synchronous setpoint"))
    if status.mode not in cia402.CYCLIC_TARGETS:
        raise Conflict(_("Choose interpolated position (7) or a cyclic synchronous mode (8, 9 or 10) first; it is in "
                         "{mode}.").format(mode=status.mode_label or _("no mode")))
    target = cia402.CYCLIC_TARGETS[status.mode]
    if session.nmt_state(node.node_id)[0] != "Operational":
        raise Conflict(_("Node {node} takes RPDOs only in NMT Operational: start it first (Plant page).").format(
            node=node.node_id))
    scale = await drive_control.setpoint_scale(session, node, status.mode)
    drive_control.check_range(value, scale)
    data = live.service(session)
    configs = await data.load(node.node_id)
    config = next((c for c in configs if c.direction == "rpdo" and c.valid and
                   {cia402.CONTROL_WORD, target} <= {entry.ref for entry in c.entries}), None)
    if config is None:
        raise Conflict(_("No valid RPDO of node {node} maps the control word 0x6040 and {target}: map one on the PDO "
                         "tab.").format(node=node.node_id, target=target))
    drive_control.require_confirmation(confirm, node.node_id, _("Cyclic setpoint {value} {unit}").format(
        value=f"{value:g}", unit=scale.unit), {**drive_control.sent(node, target, value, scale.unit),
                                                "RPDO": config.number})
    guard_for(session).arm(node.node_id, panel)
    period = await _cycle_ms(session, node)
    word = await drive_control.last_control_word(session, node) & ~MODE_BITS
    word |= ENABLE_IP_MODE if status.mode == 7 else 0
    if panel.key not in data.watchers:
        data.watch(panel.key)
    data.start_sync(period)
    frame = await data.start_cyclic(panel.key, node.node_id, config.number,
                                    {cia402.CONTROL_WORD: str(word), target: f"{value:g}"}, period)
    return CyclicStream(mode=status.mode, rpdo=config.number, cob_id=config.cob_id, period_ms=period,
                        data=frame.hex(" ").upper())


def stop_stream(session: Session, node: SessionNode) -> int:
    """End the cyclic RPDOs to the node (a stopping command does it too); how many ran."""
    return live.service(session).stop_node(node.node_id)
