"""Drive control service against the simulated demo plant (node 3 MICROMASTER 440, 12 8200 vector + EMF2178IB,
5 8400 motec) through the real SDO path: state from the status word, transitions, setpoint, modes, interlocks."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Coroutine
from typing import Any, TypeVar

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, Conflict, OutOfRange
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_control, drive_guard
from drivebench.services.control.drive_control import DriveStatus, describe
from drivebench.services.control.drive_words import Command, Family, family_of_profile
from drivebench.simulator.plant import Plant
from tests.confirming import confirmed_call
from tests.services.conftest import set_up
from tests.write_contexts import SERVICE

T = TypeVar("T")
MM, VECTOR, MOTEC = 3, 12, 5


def _family(profile_id: str) -> Family:
    """The drive control a shipped profile's control section describes."""
    found = family_of_profile(ProfileRegistry().get(profile_id))
    assert found is not None
    return found


CIA402 = _family("siemens-micromaster4-canopen")
EMF = _family("lenze-8200-vector-emf2178ib")
L8400 = _family("lenze-8400-motec-canopen")


class Bench:
    def __init__(self, runner: asyncio.Runner, session: Session, plant: Plant) -> None:
        self.runner, self.session, self.plant = runner, session, plant

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self.runner.run(coro)

    def status(self, node_id: int) -> DriveStatus:
        return self.run(drive_control.read_status(self.session, self.session.node(node_id)))

    def command(self, node_id: int, which: Command, confirm: bool = False) -> DriveStatus:
        """``confirm`` names the node, as the safety interlock wants it."""
        node = self.session.node(node_id)
        if not confirm:
            return self.run(drive_control.command(self.session, node, which, ctx=SERVICE))
        return self.run(confirmed_call(drive_control.command, self.session, node, which, confirm=node_id, ctx=SERVICE))

    def until(self, node_id: int, state: str, timeout_s: float = 8.0) -> DriveStatus:
        deadline = time.monotonic() + timeout_s
        while (status := self.status(node_id)).state != state:
            assert time.monotonic() < deadline, f"node {node_id} stays in {status.state_label}"
            self.run(asyncio.sleep(0.05))
        return status


@pytest.fixture
def bench(plant_session: tuple[asyncio.Runner, Session], plant: Plant) -> Bench:
    return Bench(*plant_session, plant)


@pytest.mark.parametrize(("word", "state"), [
    (0xFE20, "not_ready"), (0xFE60, "switch_on_disabled"), (0xFE31, "ready"), (0xFE33, "switched_on"),
    (0xFE37, "operation_enabled"), (0xFA37, "operation_enabled"), (0xFE17, "quick_stop_active"),
    (0xFE3F, "fault_reaction_active"), (0xFE28, "fault"), (0x0008, "fault")])
def test_cia402_state_from_every_status_word(word: int, state: str) -> None:
    """Table 3-18 of the MICROMASTER manual (the traces' 0xFE31/33/37/FA37 among them)."""
    assert describe(CIA402, word)[0] == state


@pytest.mark.parametrize(("device_status", "state", "enabled", "fault"), [
    (0, "init", False, False), (2, "switch_on_inhibit", False, False), (3, "operation_inhibited", False, False),
    (4, "flying_restart", True, False), (5, "dc_brake", True, False), (6, "operation_enabled", True, False),
    (7, "message", False, True), (8, "fault", False, True), (10, "fail_qsp", False, True)])
def test_emf2178ib_state_from_every_device_status(device_status: int, state: str, enabled: bool,
                                                   fault: bool) -> None:
    assert describe(EMF, 0x8000 | device_status << 8) == (state, EMF.state_box(state).label,  # type: ignore[union-attr]
                                                           enabled, fault)


@pytest.mark.parametrize(("device_state", "state"), [(1, "init"), (3, "ready"), (4, "switched_on"),
                                                     (5, "operation_enabled"), (7, "trouble"), (8, "fault")])
def test_8400_state_from_every_device_state(device_state: int, state: str) -> None:
    assert describe(L8400, device_state << 8)[0] == state


def test_micromaster_first_run_and_back(bench: Bench) -> None:
    bench.plant.nodes[MM].store.set_ref("P1120", 1.0)  # test-only: 1 s ramp
    bench.run(set_up(bench.session, MM, "P0700", 6))
    bench.run(set_up(bench.session, MM, "P1000", 6))
    assert bench.until(MM, "switch_on_disabled").status_bits[6].set
    assert bench.command(MM, Command.SHUTDOWN).state == "ready"
    assert bench.command(MM, Command.SWITCH_ON).state == "switched_on"
    with pytest.raises(ConfirmationRequired, match="confirm"):
        bench.command(MM, Command.ENABLE_OPERATION)
    status = bench.command(MM, Command.ENABLE_OPERATION, confirm=True)
    assert status.state == "operation_enabled" and status.armed and status.control_word == 0x0F
    drive_control.guard_for(bench.session).keepalive(MM)
    with pytest.raises(OutOfRange):
        bench.run(confirmed_call(drive_control.set_setpoint, bench.session, bench.session.node(MM), 9000, confirm=MM,
                                 ctx=SERVICE))
    status = bench.run(confirmed_call(drive_control.set_setpoint, bench.session, bench.session.node(MM), 300,
                                      confirm=MM, ctx=SERVICE))
    assert status.control_word == 0x7F  # velocity mode: RFG enable/start/setpoint enable
    deadline = time.monotonic() + 8
    while (speed := bench.run(drive_control.read_actuals(bench.session, bench.session.node(MM)))[0]).value != 300:
        assert time.monotonic() < deadline, f"speed stays {speed.value}"
        drive_control.guard_for(bench.session).keepalive(MM)
        bench.run(asyncio.sleep(0.05))
    assert speed.label == "Speed" and speed.unit == "rpm"
    status = bench.command(MM, Command.DISABLE_OPERATION)
    assert status.state == "switched_on" and not status.armed
    assert bench.command(MM, Command.SHUTDOWN).state == "ready"


def test_keepalive_lost_sends_quick_stop(bench: Bench) -> None:
    bench.run(set_up(bench.session, MM, "P0700", 6))
    bench.until(MM, "switch_on_disabled")
    bench.command(MM, Command.SHUTDOWN)
    bench.command(MM, Command.ENABLE_OPERATION, confirm=True)  # from ready: on by itself (manual ch. 3.3)
    guard = drive_control.guard_for(bench.session)
    assert guard.armed(MM)
    deadline = time.monotonic() + drive_control.KEEPALIVE_TIMEOUT_S + 8
    while MM not in guard.trips:
        assert time.monotonic() < deadline, "no quick stop after the keep-alive stopped"
        bench.run(asyncio.sleep(0.1))
    assert "Quick stop sent" in guard.trips[MM]  # named before the write returns (status reads name it at once)
    drive = bench.plant.nodes[MM].drive
    assert drive is not None
    deadline = time.monotonic() + 5
    while drive.control_word & 0x06 != 0x02:  # quick stop command (bit 2 = 0) on the drive
        assert time.monotonic() < deadline, f"quick stop not on the drive: control word 0x{drive.control_word:04X}"
        bench.run(asyncio.sleep(0.05))
    status = bench.until(MM, "switch_on_disabled")  # quick stop active, then stopped
    assert status.last_trip and "keep-alive" in status.last_trip


def test_a_status_read_while_the_drive_is_still_enabling_keeps_its_holder(bench: Bench) -> None:
    """A drive armed a moment ago may not be "enabled" yet (ready -> switched on -> operation enabled run on its
    own cycle): a status read in between must not disarm it, or it would run on with nobody holding it."""
    bench.run(set_up(bench.session, MM, "P0700", 6))
    bench.until(MM, "switch_on_disabled")
    guard = drive_control.guard_for(bench.session)
    anna = drive_guard.panel_of("127.0.0.1", "tab-anna", "Anna")

    async def arm() -> None:  # as an enabling command does, before the drive gets there
        guard.arm(MM, anna)

    bench.run(arm())
    status = bench.run(drive_control.read_status(bench.session, bench.session.node(MM), anna))
    assert not status.enabled and status.armed and status.you_hold, status


def test_fault_and_fault_reset(bench: Bench) -> None:
    bench.run(set_up(bench.session, MM, "P0700", 6))
    bench.until(MM, "switch_on_disabled")
    drive = bench.plant.nodes[MM].drive
    assert drive is not None
    drive.raise_fault(7)
    status = bench.until(MM, "fault")
    assert status.fault and status.status_bits[3].set and status.status_bits[3].name == "Fault"
    with pytest.raises(ConfirmationRequired):
        bench.command(MM, Command.FAULT_RESET)
    assert bench.command(MM, Command.FAULT_RESET, confirm=True).state == "switch_on_disabled"


def test_modes_of_operation_need_p1501(bench: Bench) -> None:
    node = bench.session.node(MM)
    with pytest.raises(Conflict, match="P1501"):
        bench.run(drive_control.set_mode(bench.session, node, 4, ctx=SERVICE))
    bench.run(set_up(bench.session, MM, "P1501", 0x082B000C))
    status = bench.run(drive_control.set_mode(bench.session, node, 4, ctx=SERVICE))
    assert status.mode == 4 and status.mode_label == "Profile torque mode" and status.setpoint_ref == "0x6071"


def test_8200_vector_enable_setpoint_in_hz_and_inhibit(bench: Bench) -> None:
    bench.run(set_up(bench.session, VECTOR, "C0001", 3))
    status = bench.command(VECTOR, Command.SHUTDOWN)
    assert status.state == "operation_inhibited" and status.control_word == 0x0200
    assert status.control_bits[9].name == "Controller inhibit (AIF-CTRL-CINH)" and status.control_bits[9].set
    status = bench.command(VECTOR, Command.ENABLE_OPERATION, confirm=True)
    assert status.state == "operation_enabled" and status.setpoint_unit == "Hz"
    bench.run(confirmed_call(drive_control.set_setpoint, bench.session, bench.session.node(VECTOR), 25,
                             confirm=VECTOR, ctx=SERVICE))
    assert bench.plant.nodes[VECTOR].store.get_ref("C1822/2") == 1250  # 24000 = 480 Hz
    deadline = time.monotonic() + 8
    while (actual := bench.run(drive_control.read_actuals(bench.session, bench.session.node(VECTOR)))[0]).value != 25:
        assert time.monotonic() < deadline, f"actual stays {actual.value} Hz"
        drive_control.guard_for(bench.session).keepalive(VECTOR)
        bench.run(asyncio.sleep(0.05))
    assert bench.command(VECTOR, Command.QUICK_STOP).status_bits[15].name == "Ready for operation (DCTRL1-RDY)"
    assert bench.command(VECTOR, Command.DISABLE_OPERATION).state == "operation_inhibited"


def test_8400_switch_on_enable_and_inhibit(bench: Bench) -> None:
    assert bench.until(MOTEC, "ready").family == "lenze8400"
    assert bench.command(MOTEC, Command.SWITCH_ON).state == "switched_on"
    assert bench.command(MOTEC, Command.ENABLE_OPERATION, confirm=True).state == "operation_enabled"
    assert bench.command(MOTEC, Command.DISABLE_VOLTAGE).state == "ready"


ANNA = drive_control.Panel("panel:anna", "Anna at 10.0.0.7")
BEN = drive_control.Panel("panel:ben", "Ben at 10.0.0.9")


def test_the_panel_that_armed_the_drive_holds_it(bench: Bench) -> None:
    """Anna enables: only she moves the drive and keeps it alive; Ben watches, sees who holds it, may stop it."""
    bench.run(set_up(bench.session, MM, "P0700", 6))
    bench.until(MM, "switch_on_disabled")
    node = bench.session.node(MM)
    bench.command(MM, Command.SHUTDOWN)
    status = bench.run(confirmed_call(drive_control.command, bench.session, node, Command.ENABLE_OPERATION,
                                      confirm=MM, panel=ANNA, ctx=SERVICE))
    assert status.you_hold and status.holder and status.holder.startswith("Anna at 10.0.0.7 since ")
    seen_by_ben = bench.run(drive_control.read_status(bench.session, node, BEN))
    assert seen_by_ben.armed and not seen_by_ben.you_hold and seen_by_ben.holder == status.holder
    refused = [confirmed_call(drive_control.set_setpoint, bench.session, node, 100, confirm=node.node_id, panel=BEN,
                              ctx=SERVICE),
               drive_control.set_setpoint(bench.session, node, 0, panel=BEN, ctx=SERVICE),
               confirmed_call(drive_control.jog, bench.session, node, 1, confirm=node.node_id, panel=BEN, ctx=SERVICE),
               confirmed_call(drive_control.set_mode, bench.session, node, 2, confirm=node.node_id, panel=BEN,
                              ctx=SERVICE),
               confirmed_call(drive_control.command, bench.session, node, Command.ENABLE_OPERATION,
                              confirm=node.node_id, panel=BEN, ctx=SERVICE)]
    for attempt in refused:
        with pytest.raises(Conflict, match=r"held by Anna at 10\.0\.0\.7"):
            bench.run(attempt)
    guard = drive_control.guard_for(bench.session)
    assert not guard.keepalive(MM, BEN) and guard.keepalive(MM, ANNA)
    bench.run(confirmed_call(drive_control.set_setpoint, bench.session, node, 100, confirm=node.node_id, panel=ANNA,
                             ctx=SERVICE))
    assert bench.plant.nodes[MM].store.get_ref("0x6042") == 100
    stopped = bench.run(drive_control.command(bench.session, node, Command.QUICK_STOP, panel=BEN, ctx=SERVICE))
    assert not stopped.armed and stopped.holder is None  # any panel may stop the drive; that frees it
    bench.until(MM, "switch_on_disabled")
    bench.command(MM, Command.SHUTDOWN)
    status = bench.run(confirmed_call(drive_control.command, bench.session, node, Command.ENABLE_OPERATION,
                                      confirm=node.node_id,
                                             panel=BEN, ctx=SERVICE))
    assert status.you_hold and status.holder and status.holder.startswith("Ben")
    bench.command(MM, Command.DISABLE_VOLTAGE)


def test_only_the_holders_last_panel_closing_trips(bench: Bench) -> None:
    """Websocket bookkeeping of the guard: watchers come and go, the holder's second tab closing is no trip."""
    guard = drive_control.Guard(bench.session)
    guard.holders[MM], guard.deadlines[MM] = drive_control.Holder(ANNA, time.time()), time.monotonic() + 60
    guard.opened(MM, ANNA)
    guard.opened(MM, ANNA)
    guard.opened(MM, BEN)
    assert guard.panels(MM) == 3 and guard.panels(VECTOR) == 0
    assert not guard.closed(MM, BEN)
    assert not guard.closed(MM, ANNA)
    assert guard.closed(MM, ANNA)
    assert guard.panels(MM) == 0


def test_8200_vector_jogs_with_its_own_jog1(bench: Bench) -> None:
    """EMF2178IB ch. 9.3.1.1: AIF-CTRL bits 1/0 = 01 select NSET1-JOG1 (C0037, 20 Hz here), bit 2 reverses."""
    node = bench.session.node(VECTOR)
    bench.run(set_up(bench.session, VECTOR, "C0001", 3))
    bench.command(VECTOR, Command.SHUTDOWN)
    bench.command(VECTOR, Command.ENABLE_OPERATION, confirm=True)
    plan = bench.run(drive_control.jog_plan(bench.session, node))
    assert plan.method == "device" and plan.value == 20 and plan.unit == "Hz" and "C0037" in plan.text
    with pytest.raises(ConfirmationRequired, match="confirm"):
        bench.run(drive_control.jog(bench.session, node, 1, ctx=SERVICE))
    for direction, hz in ((1, 20), (-1, -20), (0, 0)):
        status = bench.run(confirmed_call(drive_control.jog, bench.session, node, direction, confirm=node.node_id,
                                          ctx=SERVICE))
        assert status.control_word is not None
        assert status.control_word & 0x07 == {1: 0x01, -1: 0x05, 0: 0x00}[direction]
        assert bench.plant.nodes[VECTOR].store.get_ref("C1822/2") == 0  # no setpoint: the device's JOG1 runs
        deadline = time.monotonic() + 20  # the ramp through 0 to -20 Hz, read beside three other workers
        while (actual := bench.run(drive_control.read_actuals(bench.session, node))[0]).value != hz:
            assert time.monotonic() < deadline, f"actual stays {actual.value} Hz, expected {hz}"
            drive_control.guard_for(bench.session).keepalive(VECTOR)
            bench.run(asyncio.sleep(0.05))
    bench.command(VECTOR, Command.DISABLE_OPERATION)


def test_jog_plans_of_the_other_devices(bench: Bench) -> None:
    """No jog bits in the MICROMASTER or 8400 CANopen manuals: setpoint jog, the 8400 at its C00039/1 JOG1 value."""
    motec = bench.run(drive_control.jog_plan(bench.session, bench.session.node(MOTEC)))
    assert motec.method == "setpoint" and motec.value == 600 and "C00039/1" in motec.text  # 40 % of 1500 rpm
    micromaster = bench.run(drive_control.jog_plan(bench.session, bench.session.node(MM)))
    assert micromaster.method == "setpoint" and micromaster.value == 150 and "no jog" in micromaster.text
