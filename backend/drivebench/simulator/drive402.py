"""CiA 402 device control of a simulated MICROMASTER 4: the drive state machine, velocity and profile torque mode.

The control word 0x6040 may arrive by SDO or by RPDO (both end in a store write, which calls :meth:`on_write`);
the status word 0x6041 is rewritten after every transition, and the actual values follow the setpoints in
the process-data cycle of the drive (8 ms, MICROMASTER manual ch. 3.4: "process data reach the drive every 8 ms").

Manual facts built in (seed 003, ch. 3.3, tables 3-15...3-18, traces of ch. 5.7/5.8):
* Device control commands per table 3-16; fault reset is the rising edge of bit 7.
* "The drive does not require a second command to progress from ready to switch on to operation enabled": with
  enable operation (0x0F) in *ready to switch on* it shows *switched on* and then moves on by itself.
* The control word acts only with P0700 = 6 (command source CAN); 0x6042 only with P1000 = 6.
* Bits 4/5/6 (RFG enable / start / setpoint enable) exist in velocity mode only; 0x7F runs the ramp.
* Status word high byte as the traces show it: 0xFE (bits 9, 11...15 set, bit 10 target reached), 0xFA while
  the ramp runs. Bit 4: table 3-17 names it "voltage disabled" (MM OFF2 active), but every trace frame (0x31,
  0x33, 0x37 with the voltage enabled) has it set; CiA 402 ("voltage enabled") and the traces agree, so the
  simulator sets it while control word bit 1 (enable voltage) is 1.
* After power-up the drive passes *not ready to switch on* and stands in *switch on disabled* (CiA 402 transition
  1, table 3-18). The torque chapter's first frame 0xFE31 (ready) follows the velocity chapter's shutdown.
* 0x6060 acts only once P1501 = r2091.12 (0x082B000C); values other than 2 and 4 are ignored (table 3-20).
  In profile torque mode (4) 0x6071 acts once P1503 = r2050.4 (0x08020004).
"""

from __future__ import annotations

import threading
from enum import Enum

from drivebench.errors import UnknownParameter
from drivebench.simulator.host import DeviceHost
from drivebench.simulator.motor_model import MotorModel, load_torque
from drivebench.simulator.store import RawValue

CYCLE_S = 0.008
MAX_STEP_S = 0.25
"""A late cycle (a loaded machine) ramps for the time that passed since the last one, up to this much: the ramp
takes the drive's ramp-up time, not a number of cycles."""
BICO_TORQUE_CONTROL = 0x082B000C  # r2091.12 -> P1501
BICO_TORQUE_SETPOINT = 0x08020004  # r2050.4 -> P1503
RATED_CURRENT_A = 1.9  # demo motor: 0.75 kW, 4 poles, 400 V (an assumption) while P0305 holds no rated current


class State402(Enum):
    NOT_READY_TO_SWITCH_ON = "Not ready to switch on"
    SWITCH_ON_DISABLED = "Switch on disabled"
    READY_TO_SWITCH_ON = "Ready to switch on"
    SWITCHED_ON = "Switched on"
    OPERATION_ENABLED = "Operation enabled"
    QUICK_STOP_ACTIVE = "Quick stop active"
    FAULT_REACTION_ACTIVE = "Fault reaction active"
    FAULT = "Fault"


# Bits 0, 1, 2, 3, 5, 6 per state (table 3-18; 'X' bits: quick stop = 1 outside quick stop active).
STATE_BITS = {
    State402.NOT_READY_TO_SWITCH_ON: 0x0020,
    State402.SWITCH_ON_DISABLED: 0x0060,
    State402.READY_TO_SWITCH_ON: 0x0021,
    State402.SWITCHED_ON: 0x0023,
    State402.OPERATION_ENABLED: 0x0027,
    State402.QUICK_STOP_ACTIVE: 0x0007,
    State402.FAULT_REACTION_ACTIVE: 0x002F,
    State402.FAULT: 0x0028,
}
HIGH_BYTE = 0xFA00  # bits 9, 11..15 as in every trace frame; bit 10 (target reached) added when not ramping
TARGET_REACHED = 0x0400
MAX_FREQUENCY_REACHED = 0x0100
VOLTAGE_BIT = 0x0010
RUNS_RIGHT = 0x4000  # MM status word bit 14 "motor runs direction right" (set at rest in every trace)
REVERSE = 0x0800  # control word bit 11, MM "Reverse"


def command_state(state: State402, cw: int) -> State402:
    """The state a control word leads to from ``state`` (table 3-16, CiA 402 transitions 2...12, 16)."""
    voltage, quick, switch_on, enable = cw & 0x02, cw & 0x04, cw & 0x01, cw & 0x08
    if state in (State402.NOT_READY_TO_SWITCH_ON, State402.FAULT_REACTION_ACTIVE, State402.FAULT):
        return state
    if not voltage:  # disable voltage: 7, 9, 10, 12
        return State402.SWITCH_ON_DISABLED
    if not quick:  # quick stop: 7, 10 -> switch on disabled; 11 -> quick stop active
        if state is State402.OPERATION_ENABLED:
            return State402.QUICK_STOP_ACTIVE
        return state if state is State402.QUICK_STOP_ACTIVE else State402.SWITCH_ON_DISABLED
    if state is State402.QUICK_STOP_ACTIVE:
        return state  # leaves only by disable voltage or when stopped (12)
    if not switch_on:  # shutdown: 2, 6, 8
        return State402.READY_TO_SWITCH_ON
    if state is State402.SWITCH_ON_DISABLED:
        return state  # switch on needs shutdown first
    if not enable:  # switch on (3) / disable operation (5)
        return State402.SWITCHED_ON
    return State402.OPERATION_ENABLED  # enable operation (4); from ready via switched on (MM: automatically)


class StateMachine402:
    """What every simulated CiA 402 drive shares: its state, the last control word, states passed, fault reset."""

    def __init__(self, node: DeviceHost) -> None:
        self.node = node
        self.store = node.store
        self._lock = threading.RLock()
        self.state = State402.NOT_READY_TO_SWITCH_ON
        self.control_word = 0
        self.fault_code = 0
        self.history: list[State402] = []

    def _publish(self) -> None:
        raise NotImplementedError

    def _enter(self, state: State402) -> None:
        self.state = state
        self.history.append(state)
        self._publish()

    def _fault_reset(self, cw: int, previous: int) -> None:
        """Transition 15: a rising edge of control word bit 7 in *fault* clears 0x603F and the EMCY."""
        if cw & 0x80 and not previous & 0x80 and self.state is State402.FAULT:
            self.fault_code = 0
            if self.store.has(0x603F, 0):
                self.store.set(0x603F, 0, 0, notify=False)
            self._enter(State402.SWITCH_ON_DISABLED)
            self.node.clear_emcy()


class Drive402(StateMachine402):
    """The MICROMASTER's drive model (the profile's control section names it ``cia402_vf_inverter``)."""

    def __init__(self, node: DeviceHost) -> None:
        super().__init__(node)
        self.speed_rpm = 0.0
        self.torque_permille = 0.0
        self.ramping = False
        self._speed_before = 0.0
        self.motor = MotorModel(self._rated_current(), self._param("r0037", 35.0))
        self._next_cycle = 0.0
        self._last_cycle: float | None = None  # None: resting, the next cycle is the first of a run
        self._dt = CYCLE_S  # the time this cycle stands for
        self.store.add_write_hook(self.on_write)
        self.reset()

    # --- parameters the drive looks at --------------------------------------------------------------------
    def _param(self, ref: str, default: float) -> float:
        try:
            value = self.store.get_ref(ref)
        except UnknownParameter:
            return default
        return float(value) if isinstance(value, (int, float)) else default

    def _obj(self, index: int, default: int = 0) -> int:
        if not self.store.has(index, 0):
            return default
        value = self.store.get(index, 0)
        return int(value) if isinstance(value, (int, float)) else default

    def _rated_current(self) -> float:
        """The motor's rated current P0305 as quick commissioning set it; the demo motor's while it is 0."""
        rated = self._param("P0305", 0.0)
        return rated if rated > 0 else RATED_CURRENT_A

    def _can_control(self) -> bool:
        return self._param("P0700", 6) == 6

    def max_speed_rpm(self) -> float:
        return self._param("P1082", 50.0) * 60 / max(self._param("r0313", 2), 1)

    def _rate_rpm_s(self, down: bool) -> float:
        ramp_s = self._param("P1121" if down else "P1120", 10.0)
        return self.max_speed_rpm() / ramp_s if ramp_s > 0 else 1e9

    # --- life cycle --------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Power-up or reset node: not ready to switch on; the next cycle goes on to switch on disabled."""
        with self._lock:
            self.state = State402.NOT_READY_TO_SWITCH_ON
            self.control_word = self._obj(0x6040)
            self.speed_rpm = self.torque_permille = 0.0
            self.fault_code = 0
            self.history = [self.state]
            self._publish()

    def raise_fault(self, fault_code: int, emcy_code: int = 0x1000) -> None:
        """A drive fault (MM F-number): fault reaction active, EMCY, then fault once the motor has stopped."""
        with self._lock:
            self.fault_code = fault_code
            self._enter(State402.FAULT_REACTION_ACTIVE)
            if self.store.has(0x603F, 0):
                self.store.set(0x603F, 0, fault_code, notify=False)
        self.node.record_fault(fault_code)
        self.node.raise_emcy(emcy_code, 0x01, self.node.fault_bytes(fault_code))

    # --- control word --------------------------------------------------------------------------------------
    def on_write(self, index: int, sub: int, raw: RawValue) -> None:
        if sub == 0 and isinstance(raw, float):  # motor data (P0305) change the motor model's current
            self.motor.rated_current_a = self._rated_current()
        if sub != 0 or not isinstance(raw, int):
            return
        if index == 0x6040:
            self._on_control_word(raw & 0xFFFF)
        elif index == 0x6060:
            self._on_mode(raw)

    def _on_control_word(self, cw: int) -> None:
        with self._lock:
            previous, self.control_word = self.control_word, cw
            if not self._can_control():
                return  # P0700 != 6: the MICROMASTER takes its commands from elsewhere
            if self.state is State402.NOT_READY_TO_SWITCH_ON:
                self._enter(State402.SWITCH_ON_DISABLED)
            self._fault_reset(cw, previous)
            target = command_state(self.state, cw)
            if target is State402.OPERATION_ENABLED and self.state is State402.READY_TO_SWITCH_ON:
                self._enter(State402.SWITCHED_ON)  # shown briefly, then on by itself (ch. 3.3)
            if target is not self.state:
                self._enter(target)

    def _on_mode(self, mode: int) -> None:
        if mode not in (2, 4) or not self.store.has(0x6061, 0):
            return  # table 3-20: other values are ignored
        if self._param("P1501", BICO_TORQUE_CONTROL) != BICO_TORQUE_CONTROL:
            return  # 0x6060 acts only through CW2 bit 12 (P1501 = r2091.12)
        self.store.set(0x6061, 0, mode)
        self._publish()

    # --- status word and actual values -----------------------------------------------------------------
    def status_word(self) -> int:
        word = STATE_BITS[self.state] | HIGH_BYTE
        if self.control_word & 0x02 and self.state is not State402.NOT_READY_TO_SWITCH_ON:
            word |= VOLTAGE_BIT
        if not self.ramping:
            word |= TARGET_REACHED
        if abs(self.speed_rpm) >= self.max_speed_rpm() - 0.5:
            word |= MAX_FREQUENCY_REACHED
        if self.speed_rpm < 0:
            word &= ~RUNS_RIGHT
        return word

    def _publish(self) -> None:
        word = self.status_word()
        if self.store.get(0x6041, 0) != word:
            self.store.set(0x6041, 0, word)

    def _set_if(self, index: int, value: int) -> None:
        if self.store.has(index, 0) and self.store.get(index, 0) != value:
            self.store.set(index, 0, value)

    def _set_ref(self, ref: str, value: float) -> None:
        try:
            if self.store.get_ref(ref) != value:
                self.store.set_ref(ref, value)
        except UnknownParameter:
            pass

    def tick(self, now: float) -> None:
        if now < self._next_cycle:
            return
        self._next_cycle = now + CYCLE_S
        with self._lock:
            self._dt = CYCLE_S if self._last_cycle is None else min(max(now - self._last_cycle, CYCLE_S), MAX_STEP_S)
            self._last_cycle = now
            if self.state is State402.NOT_READY_TO_SWITCH_ON:
                self._enter(State402.SWITCH_ON_DISABLED)  # transition 1: self-test done
            if self._obj(0x6061, 2) == 4 and self.state is State402.OPERATION_ENABLED:
                self._torque_cycle()
            else:
                self._velocity_cycle()
            if self.state is State402.QUICK_STOP_ACTIVE and self.speed_rpm == 0:
                self._enter(State402.SWITCH_ON_DISABLED)  # transition 12: quick stop done
            elif self.state is State402.FAULT_REACTION_ACTIVE and self.speed_rpm == 0:
                self._enter(State402.FAULT)  # transition 14
            self._write_actuals(now)
            self._publish()

    def next_tick(self) -> float | None:
        """When the next cycle is due; None while the drive rests (no motion, no transition under way, the motor
        model settled): a write to the drive wakes the plant, which runs a cycle at once."""
        with self._lock:
            resting = (self.state not in (State402.NOT_READY_TO_SWITCH_ON, State402.QUICK_STOP_ACTIVE,
                                          State402.FAULT_REACTION_ACTIVE)
                       and self.speed_rpm == 0 and self.torque_permille == 0 and not self.pulses_on()
                       and self.motor.settled())
            if resting:
                self._last_cycle = None
        return None if resting else self._next_cycle

    def _velocity_target(self) -> tuple[float, bool]:
        """(target rpm, ramp running?) from state, control word bits 4...6 and 0x6042."""
        cw = self.control_word
        if self.state is not State402.OPERATION_ENABLED:
            return 0.0, True
        if not cw & 0x10:
            return 0.0, False  # RFG disabled: output set to zero at once
        if not cw & 0x20:
            return self.speed_rpm, True  # RFG stopped: holds its output
        if not cw & 0x40 or self._param("P1000", 6) != 6:
            return 0.0, True
        target = float(self._obj(0x6042)) * (-1 if cw & REVERSE else 1)  # bit 11: MM "Reverse" (table 3-15)
        limit = self.max_speed_rpm()
        return max(-limit, min(limit, target)), True

    def _velocity_cycle(self) -> None:
        self.torque_permille = 0.0
        target, ramped = self._velocity_target()
        if not ramped:
            self.speed_rpm = target
        else:
            fast = self.state in (State402.QUICK_STOP_ACTIVE, State402.FAULT_REACTION_ACTIVE)
            slowing = abs(target) < abs(self.speed_rpm) or target * self.speed_rpm < 0
            step = self._rate_rpm_s(slowing) * self._dt * (5 if fast else 1)
            delta = target - self.speed_rpm
            self.speed_rpm = target if abs(delta) <= step else self.speed_rpm + (step if delta > 0 else -step)
        self.ramping = abs(target - self.speed_rpm) > 0.5

    def _torque_cycle(self) -> None:
        """Profile torque mode: the torque follows 0x6071 within a few cycles; the load turns it into speed."""
        target = float(self._obj(0x6071)) if self._param("P1503", BICO_TORQUE_SETPOINT) == BICO_TORQUE_SETPOINT \
            else 0.0
        slope = self._obj(0x6087)
        step = slope * CYCLE_S if slope else abs(target - self.torque_permille) * 0.5 + 1
        delta = target - self.torque_permille
        self.torque_permille = target if abs(delta) <= step else self.torque_permille + (step if delta > 0 else -step)
        limit = self.max_speed_rpm()
        load_speed = max(-limit, min(limit, self.torque_permille * 1.5))  # a fan load: 1000 permille ~ 1500 rpm
        self.speed_rpm += (load_speed - self.speed_rpm) * 0.02
        self.ramping = abs(target - self.torque_permille) > 0.5

    def pulses_on(self) -> bool:
        """The inverter drives the motor: operation enabled, braking it in quick stop / fault reaction, or running
        it down the ramp after shutdown / disable operation (MM OFF1: the pulses stop once the motor stands)."""
        if self.state in (State402.OPERATION_ENABLED, State402.QUICK_STOP_ACTIVE, State402.FAULT_REACTION_ACTIVE):
            return True
        return abs(self.speed_rpm) > 0.5 and self.state in (State402.READY_TO_SWITCH_ON, State402.SWITCHED_ON)

    def actual_torque_permille(self) -> float:
        """Torque mode: the torque the drive sets; velocity mode: what the demo machine's load needs."""
        if self._obj(0x6061, 2) == 4 and self.state is State402.OPERATION_ENABLED:
            return self.torque_permille
        if not self.pulses_on():
            return 0.0
        change = self.speed_rpm - self._speed_before
        accelerating = 0 if abs(change) < 1e-6 else (1 if change > 0 else -1)
        return 1000 * load_torque(self.speed_rpm / self.max_speed_rpm(), accelerating)

    def _write_actuals(self, now: float) -> None:
        torque = self.actual_torque_permille()
        self._speed_before = self.speed_rpm
        electrical = self.motor.step(now, pulses=self.pulses_on(),
                                     speed_fraction=self.speed_rpm / self.max_speed_rpm(),
                                     torque_fraction=torque / 1000)
        self._set_ref("r0027", electrical.current_a)
        self._set_ref("r0026", electrical.dc_bus_v)
        self._set_ref("r0037", electrical.heat_sink_c)
        rpm = round(self.speed_rpm)
        self._set_if(0x6043, rpm)
        self._set_if(0x6044, rpm)
        reference = self._obj(0x604E, 1500) or 1500
        percent = round(self.speed_rpm / reference * 0x4000)
        self._set_if(0x6053, max(-0x8000, min(0x7FFF, percent)))
        self._set_if(0x6054, max(-0x8000, min(0x7FFF, percent)))
        self._set_if(0x6077, round(torque))
        hz = round(self.speed_rpm * max(self._param("r0313", 2), 1) / 60, 2)
        self._set_ref("r0021", hz)
        self._set_ref("r0063", hz)
        rated_nm = self._obj(0x6076, 5000) / 1000
        self._set_ref("r0080", round(torque * rated_nm / 1000, 3))
        self._set_ref("r0031", round(torque * rated_nm / 1000, 2))
