"""A CiA 402 drive without a vendor control section (node 7 of the demo plant, the generic servo of
``device_profiles/generic-cia402-servo.json``) driven through the real SDO path by the standard CiA 402 panel:
standard names, modes from 0x6502, units from 0x60A8/0x60A9, homing methods, profile position and velocity, jog,
limit switches, the following-error fault with its EMCY, quick stop, and the interlocks."""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import can
import pytest

from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, Conflict, InvalidValue, OutOfRange
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_control, motion
from drivebench.services.control.drive_control import DriveStatus
from drivebench.services.control.drive_words import Command
from drivebench.services.params import parameters
from drivebench.services.pdos import process_data as live
from drivebench.simulator.plant import Plant
from drivebench.simulator.servo402 import INDEX_AT, LIMIT_REVS, MAX_STEP_S, Servo402
from tests.confirming import confirmed_call
from tests.write_contexts import SERVICE

T = TypeVar("T")
AXIS = 7
STOP_AFTER_HOME_DEG = 360 * MAX_STEP_S + 360 ** 2 / (2 * 18_000) + 0.5
"""How far the axis goes on after the event that homes it: the last event is found at the zero-search speed
0x6099.2 = 60 rpm (360 °/s), at most one model step late (a late tick on a loaded machine integrates up to
MAX_STEP_S), then it brakes at 0x609A = 3000 rpm/s (18000 °/s²)."""
SEED_WORDS = ("MICROMASTER", "Lenze", "8400", "8200", "P0700", "EMF2178IB", "C0135", "AIF", "RFG")


class Axis:
    def __init__(self, runner: asyncio.Runner, session: Session, plant: Plant) -> None:
        self.runner, self.session, self.plant = runner, session, plant
        self.node = session.node(AXIS)
        drive = plant.nodes[AXIS].drive
        assert isinstance(drive, Servo402)
        self.drive = drive

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self.runner.run(coro)

    @contextlib.contextmanager
    def kept_alive(self) -> Iterator[Axis]:
        """A keep-alive every 0.25 s from a thread of its own while the test runs, as a client's page sends it: on a
        busy machine the test's own steps can take longer than the guard's 2 s, and the drive would be (rightly)
        stopped between them."""
        stop = threading.Event()

        def beat() -> None:
            while not stop.wait(0.25):
                drive_control.guard_for(self.session).keepalive(AXIS)

        beating = threading.Thread(target=beat, name="test-axis-keepalive", daemon=True)
        beating.start()
        try:
            yield self
        finally:
            stop.set()
            beating.join()

    def status(self) -> DriveStatus:
        return self.run(drive_control.read_status(self.session, self.node))

    def read(self, ref: str) -> Any:
        return self.run(parameters.read(self.session, AXIS, ref)).value

    def until(self, done: Callable[[DriveStatus], bool], what: str, timeout_s: float = 10.0) -> DriveStatus:
        deadline = time.monotonic() + timeout_s
        while not done(status := self.status()):
            assert time.monotonic() < deadline, f"{what}: status word 0x{status.status_word:04X} ({status.state})"
            drive_control.guard_for(self.session).keepalive(AXIS)
            self.run(asyncio.sleep(0.05))
        return status

    def enable(self) -> DriveStatus:
        self.until(lambda status: status.state == "switch_on_disabled", "power-up")
        for command in (Command.SHUTDOWN, Command.SWITCH_ON):
            self.run(drive_control.command(self.session, self.node, command, ctx=SERVICE))
        return self.run(confirmed_call(drive_control.command, self.session, self.node, Command.ENABLE_OPERATION,
                                       confirm=AXIS, ctx=SERVICE))

    def home(self, method: int) -> DriveStatus:
        drive_control.guard_for(self.session).keepalive(AXIS)  # enabled just now: within the keep-alive time
        self.run(confirmed_call(motion.home, self.session, self.node, method, confirm=AXIS, ctx=SERVICE))
        return self.until(lambda status: status.status_bits[12].set and status.status_bits[10].set,
                          f"homing with method {method}", timeout_s=20)


@pytest.fixture
def axis(plant_session: tuple[asyncio.Runner, Session], plant: Plant) -> Iterator[Axis]:
    with Axis(*plant_session, plant).kept_alive() as kept:
        yield kept


def test_standard_names_modes_units_and_no_vendor_words(axis: Axis) -> None:
    status = axis.until(lambda status: status.state == "switch_on_disabled", "power-up")
    assert status.family == "cia402-generic" and status.generic
    assert status.status_bits[12].name.startswith("Operation mode specific (pp: set-point acknowledge")
    assert status.control_bits[4].name.startswith("Operation mode specific (pp: new set-point")
    assert status.modes == {1: "Profile position", 3: "Profile velocity", 4: "Profile torque", 6: "Homing",
                            7: "Interpolated position", 8: "Cyclic synchronous position",
                            9: "Cyclic synchronous velocity", 10: "Cyclic synchronous torque"}  # 0x6502 = 0x3ED
    assert (status.setpoint_ref, status.setpoint_unit, status.setpoint_max) == ("0x607A", "°", 3600)
    assert [bit.name for bit in status.inputs[:3]] == ["Negative limit switch", "Positive limit switch", "Home switch"]
    assert (status.error_code, status.error_text) == (0, "No error")
    text = status.model_dump_json() + axis.run(motion.info(axis.session, axis.node)).model_dump_json()
    assert [word for word in SEED_WORDS if word.lower() in text.lower()] == []
    info = axis.run(motion.info(axis.session, axis.node))
    assert (info.position_unit, info.velocity_unit) == ("°", "rpm")
    assert info.quick_stop_option == "2: slow down on quick-stop ramp, then switch on disabled"
    assert info.homing_methods[35] == "Current position (no movement)"
    actuals = {value.ref: value for value in axis.run(drive_control.read_actuals(axis.session, axis.node))}
    assert (actuals["0x6064"].label, actuals["0x6064"].unit) == ("Position", "°")
    assert (actuals["0x606C"].unit, actuals["0x6079"].unit) == ("rpm", "mV")
    assert (actuals["0x60F4"].label, actuals["0x60F4"].unit) == ("Following error", "°")
    assert (actuals["0x6077"].unit, actuals["0x6078"].unit) == ("‰ of rated torque", "‰ of rated current")
    assert [setting.ref for setting in info.settings if setting.ref.startswith(("0x607D", "0x607F"))] == [
        "0x607D.1", "0x607D.2", "0x607F"]
    assert {setting.ref: setting.unit for setting in info.settings}["0x607D.2"] == "°"
    axis.drive.store.set(0x6061, 0, -59)  # a vendor's own mode, as a maxon drive shows it
    assert axis.status().mode_label == "manufacturer-specific (\u221259)"


def test_modes_come_from_0x6502_where_the_drive_has_it(axis: Axis) -> None:
    """The EDS lists the objects of eight modes; the drive's 0x6502 says which it supports, and that wins."""
    axis.drive.store.set(0x6502, 0, 0x0000_0025)  # bits 0, 2, 5: profile position, profile velocity, homing
    assert axis.status().modes == {1: "Profile position", 3: "Profile velocity", 6: "Homing"}
    with pytest.raises(InvalidValue, match="Mode 9 is not among this device's supported modes"):
        axis.run(drive_control.set_mode(axis.session, axis.node, 9, ctx=SERVICE))


@pytest.mark.parametrize(("without", "position", "velocity", "how"), [
    ({"0x60A8", "0x60A9"}, "position units (11.3778 increments)", "position units/s", "factor group"),
    ({"0x60A8", "0x60A9", "0x6092"}, "increments", "increments/s", "raw increments")], ids=["factor", "raw"])
def test_units_without_the_si_unit_objects(plant_session: tuple[asyncio.Runner, Session], plant: Plant,
                                           registry: ProfileRegistry, tmp_path: Path, without: set[str],
                                           position: str, velocity: str, how: str) -> None:
    """A drive without 0x60A8/0x60A9 is shown in position units of its factor group (4096 increments per
    revolution, 360 per revolution of feed), and without a feed constant in raw increments, said as such."""
    runner, session = plant_session
    data = json.loads((settings.profiles_dir / "generic-cia402-servo.json").read_text())
    data["id"] = "servo-without-si-units"
    data["objects"] = [obj for obj in data["objects"] if obj["index"] not in without]
    registry.user_profiles_dir = tmp_path
    profile = registry.add_upload("servo-without-si-units.json", json.dumps(data).encode())  # as the Profiles page
    plant.add_node(profile, 30)
    node = session.add_node(30, profile.id)
    info = runner.run(motion.info(session, node))
    assert (info.position_unit, info.velocity_unit) == (position, velocity) and how in info.units_from
    actuals = {value.ref: value.unit for value in runner.run(drive_control.read_actuals(session, node))}
    assert (actuals["0x6064"], actuals["0x606C"], actuals["0x60F4"]) == (position, velocity, position)


@pytest.mark.parametrize(("method", "near"), [(35, None), (37, None), (34, None), (33, None), (17, -LIMIT_REVS),
                                              (18, LIMIT_REVS), (1, -LIMIT_REVS), (2, LIMIT_REVS), (11, 1.0),
                                              (27, 0.5), (10, 1.0)])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_homing_methods(axis: Axis, method: int, near: float | None) -> None:
    axis.enable()
    start = axis.drive.mech
    status = axis.home(method)
    assert status.mode == 6 and status.mode_label == "Homing" and not status.status_bits[13].set
    assert axis.read("0x6098") == method
    assert abs(axis.read("0x6064")) <= STOP_AFTER_HOME_DEG  # at home: 0 ° plus the stop after the event
    revs = axis.drive.mech / axis.drive.increments_per_rev
    if near is None:
        moved = abs(axis.drive.mech - start) / axis.drive.increments_per_rev
        assert moved <= (0.02 if method in (35, 37) else 1.05)  # no motion / to the next index pulse
    else:
        assert abs(revs - near) <= (0.05 if method in (17, 18) else 1.05)  # at the switch (1, 2: next index)


def test_the_methods_offered_are_those_0x60E3_lists(axis: Axis) -> None:
    """The servo lists its 32 methods in 0x60E3; a drive that lists fewer is offered those, and another is refused
    in words before anything is written (next test)."""
    assert list(axis.run(motion.info(axis.session, axis.node)).homing_methods) == [
        *range(1, 15), *range(17, 31), 33, 34, 35, 37]


def test_a_method_0x60E3_does_not_list_is_refused_in_words(axis: Axis) -> None:
    axis.drive.store.set(0x60E3, 0, 3)  # as a drive listing 1, 2 and 3 only (read once per node: set it first)
    assert axis.run(motion.info(axis.session, axis.node)).homing_methods == {
        1: "Negative limit switch and index pulse", 2: "Positive limit switch and index pulse",
        3: "Positive home switch and index pulse (index below the switch edge)"}
    axis.enable()
    with pytest.raises(InvalidValue, match=r"Homing method 34 \(Index pulse in positive direction\) is not among "
                                           r"the supported homing methods 0x60E3 of .* \(1, 2, 3\)"):
        axis.run(confirmed_call(motion.home, axis.session, axis.node, 34, confirm=AXIS, ctx=SERVICE))
    assert axis.read("0x6098") == 35 and axis.status().mode != 6


def test_the_home_offset_is_the_position_at_home(axis: Axis) -> None:
    """CiA 402: after homing the home position reads as the home offset 0x607C."""
    axis.enable()
    axis.run(parameters.write(axis.session, AXIS, "0x607C", 90, ctx=SERVICE))
    axis.home(34)
    assert abs(axis.read("0x6064") - 90) <= STOP_AFTER_HOME_DEG  # plus the stop after the index pulse
    at_home = axis.drive.home + 90 * axis.drive.per_unit  # the index pulse found: 0x6064 = 90 ° there
    assert round(at_home - INDEX_AT) % axis.drive.increments_per_rev == 0


def test_a_home_switch_method_started_away_from_its_switch_ends_in_a_homing_error(axis: Axis) -> None:
    """Method 3 seeks a positive home switch: the switch is off above the cam, so it starts positive, runs onto the
    positive limit switch and (CiA 402 gives 3 ... 6 no reversal there) reports homing error, status bit 13."""
    axis.enable()
    axis.run(confirmed_call(motion.home, axis.session, axis.node, 3, confirm=AXIS, ctx=SERVICE))
    status = axis.until(lambda status: status.status_bits[13].set, "homing error", timeout_s=20)
    assert not status.status_bits[12].set and status.inputs[1].name == "Positive limit switch"
    assert axis.drive.demand == LIMIT_REVS * axis.drive.increments_per_rev


def test_profile_position_absolute_relative_and_target_reached(axis: Axis) -> None:
    axis.enable()
    axis.home(35)
    axis.run(confirmed_call(motion.move, axis.session, axis.node, 720, confirm=AXIS, ctx=SERVICE))
    status = axis.until(lambda status: status.status_bits[10].set and axis.read("0x6064") == 720, "at 720 °")
    assert status.mode == 1 and not status.status_bits[12].set  # set-point acknowledge taken back with bit 4
    axis.run(confirmed_call(motion.move, axis.session, axis.node, -90, relative=True, velocity=300, confirm=AXIS,
                            ctx=SERVICE))
    axis.until(lambda status: status.status_bits[10].set and axis.read("0x6064") == 630, "at 630 °")
    assert axis.read("0x6081") == 300
    with pytest.raises(OutOfRange, match="software position limits"):
        axis.run(confirmed_call(motion.move, axis.session, axis.node, 5000, confirm=AXIS, ctx=SERVICE))
    with pytest.raises(OutOfRange, match="0x607F"):
        axis.run(confirmed_call(motion.move, axis.session, axis.node, 0, velocity=9000, confirm=AXIS, ctx=SERVICE))


def test_profile_velocity_and_jog_at_a_user_set_speed(axis: Axis) -> None:
    axis.enable()
    axis.run(confirmed_call(drive_control.set_mode, axis.session, axis.node, 3, confirm=AXIS, ctx=SERVICE))
    status = axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 300, confirm=AXIS,
                                     ctx=SERVICE))
    assert (status.setpoint_ref, status.setpoint_unit, status.setpoint_max) == ("0x60FF", "rpm", 3000)
    axis.until(lambda status: status.status_bits[10].set and axis.read("0x606C") == 300, "at 300 rpm")
    axis.run(drive_control.set_setpoint(axis.session, axis.node, 0, ctx=SERVICE))
    plan = axis.run(drive_control.jog_plan(axis.session, axis.node))
    assert (plan.method, plan.value, plan.unit, plan.maximum) == ("profile_velocity", 300, "rpm", 3000)
    with pytest.raises(ConfirmationRequired):
        axis.run(drive_control.jog(axis.session, axis.node, 1, speed=120, ctx=SERVICE))
    with pytest.raises(OutOfRange, match="0x607F"):
        axis.run(confirmed_call(drive_control.jog, axis.session, axis.node, 1, speed=5000, confirm=AXIS, ctx=SERVICE))
    axis.run(confirmed_call(drive_control.jog, axis.session, axis.node, -1, speed=120, confirm=AXIS, ctx=SERVICE))
    axis.until(lambda _: axis.read("0x606C") == -120, "jogging at -120 rpm")
    axis.run(drive_control.jog(axis.session, axis.node, 0, ctx=SERVICE))
    axis.until(lambda _: axis.read("0x606C") == 0, "jog released")


def no_software_limits(axis: Axis) -> None:
    """0x607D = 0/0 (none): a run long enough to reach a switch or top speed is not stopped at ±3600 ° first."""
    for ref in ("0x607D.1", "0x607D.2"):
        axis.run(parameters.write(axis.session, AXIS, ref, 0, ctx=SERVICE))


def test_a_limit_switch_stops_the_axis(axis: Axis) -> None:
    no_software_limits(axis)
    axis.enable()
    axis.run(confirmed_call(drive_control.set_mode, axis.session, axis.node, 3, confirm=AXIS, ctx=SERVICE))
    axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 3000, confirm=AXIS, ctx=SERVICE))
    status = axis.until(lambda status: status.status_bits[11].set, "internal limit active at the switch")
    assert status.inputs[1].set and axis.read("0x606C") == 0
    # away from it: free
    axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, -300, confirm=AXIS, ctx=SERVICE))
    axis.until(lambda status: not status.inputs[1].set and not status.status_bits[11].set, "off the switch")


def test_following_error_faults_with_emcy_and_fault_reset_clears_it(axis: Axis) -> None:
    frames: list[bytes] = []
    seen = threading.Event()

    class Emcy(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id == 0x80 + AXIS:
                frames.append(bytes(msg.data))
                seen.set()

    tap = Emcy()
    axis.session.add_frame_listener(tap)
    try:
        axis.enable()
        axis.home(35)
        axis.drive.jam()
        axis.run(confirmed_call(motion.move, axis.session, axis.node, 360, confirm=AXIS, ctx=SERVICE))
        status = axis.until(lambda status: status.state == "fault", "following error fault")
        assert (status.error_code, status.error_text) == (0x8611, "Following error")
        assert seen.wait(5) and frames[0][:2] == bytes([0x11, 0x86])
        axis.drive.jam(False)
        status = axis.run(confirmed_call(drive_control.command, axis.session, axis.node, Command.FAULT_RESET,
                                         confirm=AXIS, ctx=SERVICE))
        assert status.state == "switch_on_disabled" and status.error_code == 0
    finally:
        axis.session.remove_frame_listener(tap)


def test_quick_stop_decelerates_then_switches_on_disabled(axis: Axis) -> None:
    no_software_limits(axis)
    axis.enable()
    axis.run(confirmed_call(drive_control.set_mode, axis.session, axis.node, 3, confirm=AXIS, ctx=SERVICE))
    axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 1500, confirm=AXIS, ctx=SERVICE))
    axis.until(lambda _: axis.read("0x606C") == 1500, "at 1500 rpm")
    status = axis.run(drive_control.command(axis.session, axis.node, Command.QUICK_STOP, ctx=SERVICE))
    assert not status.armed
    axis.until(lambda status: status.state == "switch_on_disabled", "stopped by the quick-stop ramp (0x6085)")
    assert state_history(axis)[-2:] == ["Quick stop active", "Switch on disabled"]
    assert axis.read("0x606C") == 0


def state_history(axis: Axis) -> list[str]:
    return [state.value for state in axis.drive.history]


def test_moves_need_the_holder_and_the_confirmation(axis: Axis) -> None:
    axis.enable()
    with pytest.raises(ConfirmationRequired, match="node 7"):
        axis.run(motion.home(axis.session, axis.node, 35, ctx=SERVICE))
    other = drive_control.Panel("panel:other", "someone else")
    with pytest.raises(Conflict, match="held by"):
        axis.run(confirmed_call(motion.move, axis.session, axis.node, 10, confirm=AXIS, panel=other, ctx=SERVICE))


def test_an_idle_axis_sleeps(axis: Axis) -> None:
    """Nothing moves, nothing changes: the model skips its cycle (the plant's tick costs one comparison)."""
    axis.until(lambda status: status.state == "switch_on_disabled", "power-up")
    deadline = time.monotonic() + 5
    while not axis.drive._idle:
        assert time.monotonic() < deadline, "the idle axis keeps stepping its model"
        time.sleep(0.02)


def test_a_setpoint_alone_is_refused_where_the_drive_needs_a_move(axis: Axis) -> None:
    axis.enable()
    with pytest.raises(InvalidValue, match="move"):
        axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 90, confirm=AXIS, ctx=SERVICE))


def test_cyclic_synchronous_velocity_through_sync_and_an_rpdo(axis: Axis) -> None:
    axis.enable()
    axis.run(confirmed_call(drive_control.set_mode, axis.session, axis.node, 9, confirm=AXIS, ctx=SERVICE))
    with pytest.raises(Conflict, match="Operational"):
        axis.run(confirmed_call(motion.stream, axis.session, axis.node, 200, confirm=AXIS))
    axis.run(axis.session.nmt(NmtCommand.START, AXIS))
    axis.until(lambda _: axis.session.nmt_state(AXIS)[0] == "Operational", "node 7 operational")
    sent = axis.run(confirmed_call(motion.stream, axis.session, axis.node, 200, confirm=AXIS))
    assert (sent.rpdo, sent.cob_id, sent.period_ms) == (3, 0x407, 10)  # RPDO3: 0x6040 + 0x60FF; 0x60C2 = 10 ms
    assert sent.data == "0F 00 C8 00 00 00"
    axis.until(lambda _: axis.read("0x606C") == 200, "following the cyclic target velocity")
    assert live.service(axis.session).sync_period_ms == 10
    status = axis.run(drive_control.command(axis.session, axis.node, Command.QUICK_STOP, ctx=SERVICE))
    assert not live.service(axis.session).cyclic_cob_ids()  # the stream ended before the quick stop was written
    axis.until(lambda status: status.state == "switch_on_disabled", "stopped")
    assert status.control_word is not None and status.control_word & 0x06 == 0x02
    live.service(axis.session).stop_sync()


def test_profile_torque_in_per_mille(axis: Axis) -> None:
    axis.enable()
    axis.run(confirmed_call(drive_control.set_mode, axis.session, axis.node, 4, confirm=AXIS, ctx=SERVICE))
    status = axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 100, confirm=AXIS,
                                     ctx=SERVICE))
    assert (status.setpoint_ref, status.setpoint_unit, status.setpoint_max) == ("0x6071", "‰", 3000)  # 0x6072
    axis.until(lambda _: axis.read("0x606C") > 0, "the load turning under the torque")
    with pytest.raises(OutOfRange):
        axis.run(confirmed_call(drive_control.set_setpoint, axis.session, axis.node, 4000, confirm=AXIS, ctx=SERVICE))
