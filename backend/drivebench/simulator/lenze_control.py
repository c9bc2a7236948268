"""Lenze device control of a simulated 8400 motec or 8200 vector / 93XX with EMF2178IB.

The control word arrives by SDO or RPDO - both are store writes:

* 8400 motec: CAN1_IN word 1 (``C00866/1``, also ``C00876/1``: LP_CanIn1_wIn1 = wCtrl), word 2 the speed
  setpoint in % of the motor reference speed C00011 (0x4000 = 100 %); CAN1_OUT word 1 (``C00868/1``) the status
  word, word 2 the actual speed (same scaling). The EtherCAT unit has no CAN1 words: MCI_IN words ``C00876/1..2``
  in, and its display of the words to the master ``C13850/1..2`` out (the preconfigured interconnection, C00007
  = 40; our reading, the EtherCAT manual names no word's meaning). The communication manual names only "wCtrl";
  the bit layout is the 8400 device control of the network (LA_NCtrl) word: see :class:`SwitchOnStates`.
* EMF2178IB: the control word ``C0135`` (SDO, 8200 vector) or AIF-IN word 1 ``C1822/1`` (RPDO1, 8200 vector and
  93XX), AIF-IN.W1 ``C1822/2`` the setpoint; status word ``C0150`` and AIF-OUT word 1 ``C1823/1``, AIF-OUT.W1
  ``C1823/2`` the actual value. Bits per the EMF2178IB manual (ch. 9.3.1): 3 QSP, 9 CINH, 10 TRIP-SET, 11 TRIP-RESET
  (rising edge); status bits 8...11 the device status (0 initialisation, 2 switch-on inhibit, 3 operation
  inhibited, 6 operation enabled, 8 fault active ...). 8200 vector: 24000 = 480 Hz (50 per Hz); 93XX:
  16383 = 100 % of the maximum speed. Process data act once C0001 = 3 (8200 vector) or C0005 = xxx3 (93XX); with
  C0142 = 0 (93XX) the controller stays inhibited after mains on or a fault until CINH has been set once.

Which words a drive has, how it scales them and which of the two state machines runs them is the table ``MODELS``,
keyed by the drive model a profile's control section names (``simulation``). The state machines are written here
from the manuals, not read from the profile, so the tool's guard and this simulator do not share one reading.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Protocol

from drivebench.errors import UnknownParameter
from drivebench.simulator.host import DeviceHost
from drivebench.simulator.motor_model import MotorModel, load_torque
from drivebench.simulator.store import RawValue

CYCLE_S = 0.004
MAX_STEP_S = 0.25
"""A late cycle (a loaded machine) ramps for the time that passed since the last one, up to this much: the ramp
takes the drive's acceleration time, not a number of cycles (a drive ramped 4 ms per cycle ran 10x slow under load)."""

# Device states of the switch-on machine (8400: C00137, status word bits 8...11, 8400 reference manual table 4-1)
INIT, READY_TO_SWITCH_ON, SWITCHED_ON, OPERATION_ENABLED, TROUBLE, DEVICE_FAULT = 1, 3, 4, 5, 7, 8
# Device status of the inhibit machine (EMF2178IB: bits 8...11)
SWITCH_ON_INHIBIT, OPERATION_INHIBITED, OPERATION_ENABLED_AIF, FAULT_ACTIVE = 2, 3, 6, 8
DEMO_RATED_CURRENT_A = 2.4  # demo 8200 vector E82EV751 (0.75 kW): no rated-current code in the profile, assumed


class StateMachine(Protocol):
    """One manual's device control: the states the control word leads to and the status word it shows."""

    fault: int
    running: int
    mode_gated: bool
    """Process data act only once the operating mode says so (C0001 = 3 / C0005 = xxx3)."""

    def start(self, control: WordControl) -> int: ...
    def after_reset(self, control: WordControl) -> int: ...
    def evaluate(self, control: WordControl) -> int | None: ...
    def target(self, control: WordControl) -> float: ...
    def status_bits(self, control: WordControl, actual: int) -> int: ...


@dataclass(frozen=True)
class DriveWords:
    """Where a drive keeps its words, how it scales them and which state machine runs them."""

    machine: StateMachine
    control_refs: tuple[str, ...]
    setpoint_refs: tuple[str, ...]
    status_refs: tuple[str, ...]
    actual_refs: tuple[str, ...]
    electrical_refs: tuple[str, str, str]
    """Motor current, DC-bus voltage, heat-sink temperature (codes the profile may or may not have)."""
    quick_stop_bit: int
    inhibit_bit: int
    fail_bit: int
    reset_bit: int
    ccw_bit: int | None
    parameter_set_bits: tuple[int, int] | None = None
    """Control-word bits that change over the parameter set (8200 vector AIF-CTRL bit 12 DCTRL1-PAR2/4, bit 13
    DCTRL1-PAR3/4, EMF2178IB manual §9.3.1.1): active set = 1 + bit 12 + 2 x bit 13, where the profile has sets."""
    full_scale: int | None = None
    """Raw setpoint of 100 % where the words fix it (8400: 0x4000 = C00011); None: 24000 = 480 Hz where the profile
    has C0001 (8200 vector), else 16383 (93XX), and the top speed is C0011 fmax where the profile has it."""
    ramp_s: float | None = None
    """0 -> 100 % in this time where the profile has no acceleration time (8400); None: C0012 and C0011."""
    rated_current_ref: str | None = None
    """The motor's rated current code; without one (or its value) ``rated_current_a``."""
    rated_current_a: float = DEMO_RATED_CURRENT_A


class SwitchOnStates:
    """8400 device control of the network word (LA_NCtrl; states C00137, reference manual table 4-1): bit 0
    SwitchOn and bit 3 EnableOperation lead from ready to switch on to operation enabled, the inhibit bit holds the
    drive ready; process data act at once, and a reset fault leaves it ready to switch on."""

    fault = DEVICE_FAULT
    running = OPERATION_ENABLED
    mode_gated = False

    def start(self, control: WordControl) -> int:
        return READY_TO_SWITCH_ON

    def after_reset(self, control: WordControl) -> int:
        return READY_TO_SWITCH_ON

    def evaluate(self, control: WordControl) -> int | None:
        cw = control.control_word
        if control.bit(cw, control.words.inhibit_bit) or not cw & 0x01:
            return READY_TO_SWITCH_ON
        return SWITCHED_ON if not cw & 0x08 else OPERATION_ENABLED

    def target(self, control: WordControl) -> float:
        sign = -1 if control.bit(control.control_word, control.words.ccw_bit) else 1
        return float(sign * control.setpoint)

    def status_bits(self, control: WordControl, actual: int) -> int:
        state = control.device_state
        word = (not control.running) << 1  # PulseInhibit
        word |= control.quick_stop() << 4  # QuickStopIsActive
        word |= (actual == 0) << 6  # SpeedActEqual0
        word |= (state in (READY_TO_SWITCH_ON, INIT)) << 7  # ControllerInhibit
        word |= (state in (DEVICE_FAULT, TROUBLE)) << 13
        word |= (actual < 0) << 14
        word |= (state not in (DEVICE_FAULT, INIT)) << 15
        return word


class InhibitStates:
    """EMF2178IB device control (ch. 9.3.1): CINH inhibits the controller; process data act once C0001 = 3 (8200
    vector) or C0005 = xxx3 (93XX); with C0142 = 0 the controller stays inhibited after mains on or a fault until
    CINH has been set once (switch-on inhibit)."""

    fault = FAULT_ACTIVE
    running = OPERATION_ENABLED_AIF
    mode_gated = True

    def start(self, control: WordControl) -> int:
        return SWITCH_ON_INHIBIT if control.restart_protection() else OPERATION_INHIBITED

    def after_reset(self, control: WordControl) -> int:
        return OPERATION_INHIBITED if control.restart_armed else SWITCH_ON_INHIBIT

    def evaluate(self, control: WordControl) -> int | None:
        if not control.process_data_active() or control.bit(control.control_word, control.words.inhibit_bit):
            return (OPERATION_INHIBITED if control.restart_armed or control.device_state != SWITCH_ON_INHIBIT
                    else SWITCH_ON_INHIBIT)
        if control.restart_armed or control.device_state == OPERATION_ENABLED_AIF:
            return OPERATION_ENABLED_AIF
        return None

    def target(self, control: WordControl) -> float:
        if not control.process_data_active():
            return 0.0
        cw, node = control.control_word, control.node
        sign = -1 if control.bit(cw, control.words.ccw_bit) and _has(node, "C0001") else 1
        jog = cw & 0x03  # 8200 vector: bits 1/0 = 01/10/11 select JOG1/2/3 (C0037...C0039)
        jog_bits = _has(node, "C0001") and control.param("C0007", 0) <= 51  # C0007 > 51: freely configurable
        if jog and jog_bits and _has(node, f"C00{36 + jog}"):
            return float(sign * round(control.param(f"C00{36 + jog}", 0.0) * 50))  # Hz; 24000 = 480 Hz
        return float(sign * control.setpoint)

    def status_bits(self, control: WordControl, actual: int) -> int:
        # 8200 vector DCTRL-PAR-B0: bit 0 of the active set, binary; 93XX: current parameter set 1 (DCTRL-PAR1-0)
        sets = control.words.parameter_set_bits is not None and control.has_sets
        word = (control.parameter_set - 1) & 1 if sets else 0x0001
        word |= (not control.running) << 1  # DCTRL-IMP pulse inhibit
        if _has(control.node, "C0001"):  # 8200 vector: RFG1 = NOUT; 93XX bit 3 is MCTRL-MMAX (torque limit): 0
            word |= (abs(actual - control.target()) < 1) << 3
        word |= (abs(actual - control.target()) < 1) << 4  # RFG input = output (NSET-RFG-I=0)
        word |= (actual == 0) << 6  # DCTRL-NOUT=0
        word |= (not control.running) << 7  # DCTRL-CINH
        word |= (actual < 0) << 14  # DCTRL-CCW
        word |= (control.device_state not in (FAULT_ACTIVE, INIT)) << 15  # DCTRL-RDY
        return word


MODELS = {
    "lenze_8400": DriveWords(SwitchOnStates(), ("C00866/1", "C00876/1"), ("C00866/2", "C00876/2"),
                             ("C00868/1", "C13850/1"), ("C00868/2", "C13850/2"), ("C00054", "C00053", "C00061"),
                             quick_stop_bit=2, inhibit_bit=8, fail_bit=14, reset_bit=7, ccw_bit=10,
                             full_scale=0x4000, ramp_s=2.0, rated_current_ref="C00088", rated_current_a=10.2),
    "lenze_emf2178ib": DriveWords(InhibitStates(), ("C0135", "C1822/1"), ("C1822/2",), ("C0150", "C1823/1"),
                                  ("C1823/2",), ("C0054", "C0053", "C0061"),
                                  quick_stop_bit=3, inhibit_bit=9, fail_bit=10, reset_bit=11, ccw_bit=2,
                                  parameter_set_bits=(12, 13)),
}
"""The named drive models a profile's control section selects (``simulation``)."""


class WordControl:
    """A drive run by vendor control and status words (see the module docstring), by the state machine its words
    name."""

    def __init__(self, node: DeviceHost, words: DriveWords) -> None:
        self.node = node
        self.store = node.store
        self.words = words
        self._lock = threading.RLock()
        self._keys = {self._key(ref): ref for ref in words.control_refs + words.setpoint_refs}
        self._mode_keys = {self._key(ref) for ref in ("C0001", "C0005")} - {None}
        self.device_state = INIT
        self.control_word = 0
        self.setpoint = 0
        self.speed = 0.0  # in setpoint units (raw words)
        self.restart_armed = False
        self._published: tuple[int, int] | None = None
        self._next_cycle = 0.0
        self._last_cycle: float | None = None  # None: resting, the next cycle is the first of a run
        self.history: list[int] = []
        self._speed_before = 0.0
        rated = (self._engineering(words.rated_current_ref, words.rated_current_a) if words.rated_current_ref
                 else words.rated_current_a)
        self.motor = MotorModel(rated, self._engineering(words.electrical_refs[2], 43.0))
        self.store.add_write_hook(self.on_write)
        self.reset()

    @staticmethod
    def words_for(node: DeviceHost, model: str | None) -> DriveWords | None:
        """The words of the model a profile's control section names (``simulation``), if the device has them."""
        words = MODELS.get(model or "")
        return words if words is not None and any(_has(node, ref) for ref in words.control_refs) else None

    def _key(self, ref: str) -> tuple[int, int] | None:
        try:
            item = self.store.catalog.resolve(ref)
        except UnknownParameter:
            return None
        return item.index, item.subindex

    @property
    def parameter_set(self) -> int:
        """The active parameter set (1 ... 4) the control word selects; 1 where the profile has one set."""
        bits = self.words.parameter_set_bits
        if bits is None or not self.has_sets:
            return 1
        return 1 + self.bit(self.control_word, bits[0]) + 2 * self.bit(self.control_word, bits[1])

    @property
    def has_sets(self) -> bool:
        return self.store.catalog.parameter_sets > 1

    def param(self, ref: str, default: float) -> float:
        try:
            catalog = self.store.catalog
            item = catalog.in_set(catalog.resolve(ref), self.parameter_set)  # C0012 -> C2012 in set 2
            value = self.store.get(item.index, item.subindex)
        except UnknownParameter:
            return default
        return float(value) / 10000 if self._fix32(ref) and isinstance(value, int) else \
            float(value) if isinstance(value, (int, float)) else default

    def _engineering(self, ref: str, default: float) -> float:
        """A code's value in the manual's units (raw / factor)."""
        try:
            item = self.store.catalog.resolve(ref)
        except UnknownParameter:
            return default
        raw = self.store.get(item.index, item.subindex)
        return float(raw) / float(item.entry.factor) if isinstance(raw, (int, float)) else default

    def _set_engineering(self, ref: str, value: float) -> None:
        try:
            item = self.store.catalog.resolve(ref)
        except UnknownParameter:
            return  # e.g. the 93XX profile has no C0053/C0054
        raw = round(value * float(item.entry.factor))
        if self.store.get(item.index, item.subindex) != raw:
            self.store.set(item.index, item.subindex, raw)

    def _fix32(self, ref: str) -> bool:
        return self.store.catalog.resolve(ref).entry.factor == 10000

    def process_data_active(self) -> bool:
        if not self.words.machine.mode_gated:
            return True
        if _has(self.node, "C0001"):
            return self.param("C0001", 0) == 3
        return int(self.param("C0005", 1013)) % 10 == 3

    def restart_protection(self) -> bool:
        return _has(self.node, "C0142") and self.param("C0142", 0) == 0

    def full_scale(self) -> int:
        """Raw setpoint of 100 %: 8400 0x4000, 93XX 16383, 8200 vector 24000 (= 480 Hz)."""
        if self.words.full_scale is not None:
            return self.words.full_scale
        return 24000 if _has(self.node, "C0001") else 16383

    def ramp_per_s(self) -> float:
        if self.words.ramp_s is not None:
            return self.full_scale() / self.words.ramp_s  # 0 -> 100 % (acceleration time not in the profile)
        accel_s = self.param("C0012", 5.0) or 5.0
        top = self.param("C0011", 50.0) * 50 if _has(self.node, "C0011") else self.full_scale()
        return top / accel_s

    # --- life cycle ------------------------------------------------------------------------------------
    def reset(self) -> None:
        with self._lock:
            self.control_word = 0
            self.setpoint = 0
            self.speed = 0.0
            self.restart_armed = False
            self._published = None
            self.history = []
            self._enter(INIT)

    def raise_fault(self, error_number: int = 1) -> None:
        with self._lock:
            self._enter(self.words.machine.fault)
        self.node.record_fault(error_number)
        self.node.raise_emcy(0x1000, 0x01, self.node.fault_bytes(error_number))

    # --- words in ---------------------------------------------------------------------------------------
    def on_write(self, index: int, sub: int, raw: RawValue) -> None:
        if (index, sub) in self._mode_keys:
            with self._lock:
                self._evaluate()  # C0001 = 3 / C0005 = xxx3: the control word acts from now on
            return
        ref = self._keys.get((index, sub))
        if ref is None or not isinstance(raw, int):
            return
        if ref in self.words.control_refs:
            if ref == "C1822/1" and not self.process_data_active():
                return
            self._mirror(ref, raw, self.words.control_refs)
            self._on_control_word(raw & 0xFFFF)
        else:
            self._mirror(ref, raw, self.words.setpoint_refs)
            with self._lock:
                self.setpoint = raw - 0x10000 if raw >= 0x8000 else raw

    def _mirror(self, ref: str, raw: int, refs: tuple[str, ...]) -> None:
        for other in refs:
            key = self._key(other)
            if other != ref and key is not None and self.store.get(*key) != raw:
                self._set_word(key, raw, notify=False)

    def _set_word(self, key: tuple[int, int], raw: int, *, notify: bool = True) -> None:
        signed = self.store.slot(*key).data_type.name.startswith("INTEGER")
        value = raw - 0x10000 if signed and raw >= 0x8000 else raw & 0xFFFF if not signed else raw
        self.store.set(key[0], key[1], value, notify=notify)

    @staticmethod
    def bit(word: int, bit: int | None) -> bool:
        return bit is not None and bool(word >> bit & 1)

    def _on_control_word(self, cw: int) -> None:
        words = self.words
        with self._lock:
            previous, self.control_word = self.control_word, cw
            if self.bit(cw, words.fail_bit) and not self.bit(previous, words.fail_bit):
                self.raise_fault(0x10)  # TRIP-SET / SetFail: external fault
                return
            if self.device_state == words.machine.fault:
                if self.bit(cw, words.reset_bit) and not self.bit(previous, words.reset_bit):
                    self.restart_armed = not self.restart_protection()
                    self._enter(words.machine.after_reset(self))
                    self.node.clear_emcy()
                return
            if self.bit(cw, words.inhibit_bit):
                self.restart_armed = True
            self._evaluate()

    def _evaluate(self) -> None:
        if self.device_state in (INIT, self.words.machine.fault):
            return
        state = self.words.machine.evaluate(self)
        if state is not None:
            self._enter(state)

    def _enter(self, state: int) -> None:
        if state != self.device_state or not self.history:
            self.device_state = state
            self.history.append(state)
        self._publish()

    # --- words out --------------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self.device_state == self.words.machine.running

    def quick_stop(self) -> bool:
        return self.bit(self.control_word, self.words.quick_stop_bit)

    def target(self) -> float:
        if not self.running or self.quick_stop():
            return 0.0
        return self.words.machine.target(self)

    def status_word(self) -> int:
        actual = round(self.speed)
        return (self.device_state & 0x0F) << 8 | self.words.machine.status_bits(self, actual)

    def _publish(self) -> None:
        word, actual = self.status_word(), max(-0x8000, min(0x7FFF, round(self.speed)))
        if (word, actual) == self._published:
            return  # the words are written when they change, as the drive's process image does
        self._published = (word, actual)
        for ref in self.words.status_refs:
            key = self._key(ref)
            if key is not None:
                current = self.store.get(*key)
                if not isinstance(current, int) or current & 0xFFFF != word:
                    self._set_word(key, word)
        for ref in self.words.actual_refs:
            key = self._key(ref)
            if key is not None and self.store.get(*key) != actual:
                self._set_word(key, actual & 0xFFFF)  # an UNSIGNED16 display word (C13850/2) holds it as 16 bits

    def tick(self, now: float) -> None:
        if now < self._next_cycle:
            return
        self._next_cycle = now + CYCLE_S
        with self._lock:
            dt = CYCLE_S if self._last_cycle is None else min(max(now - self._last_cycle, CYCLE_S), MAX_STEP_S)
            self._last_cycle = now
            if self.device_state == INIT:
                self.restart_armed = not self.restart_protection()
                self._enter(self.words.machine.start(self))
                self._evaluate()
            target = self.target()
            fast = self.quick_stop() or not self.running
            step = self.ramp_per_s() * dt * (4 if fast else 1)
            delta = target - self.speed
            self.speed = target if abs(delta) <= step else self.speed + (step if delta > 0 else -step)
            self._publish()
            self._write_electrical(now)

    def next_tick(self) -> float | None:
        """When the next cycle is due; None while the drive rests (stopped, pulses inhibited, motor model settled):
        a write to the drive wakes the plant, which runs a cycle at once."""
        with self._lock:
            resting = self.device_state != INIT and self.speed == 0 and not self.running and self.motor.settled()
            if resting:
                self._last_cycle = None
        return None if resting else self._next_cycle

    def speed_fraction(self) -> float:
        """Actual speed as a fraction of the top speed (8400: C00011 = 0x4000; 8200 vector: C0011 fmax)."""
        if self.words.full_scale is None and _has(self.node, "C0011"):
            top = self.param("C0011", 50.0) * 50
        else:
            top = float(self.full_scale())
        return self.speed / top if top else 0.0

    def _write_electrical(self, now: float) -> None:
        """Motor current, DC-bus voltage, heat sink: current only while the pulses are enabled (see motor_model)."""
        change = self.speed - self._speed_before
        self._speed_before = self.speed
        accelerating = 0 if abs(change) < 1e-6 else (1 if change > 0 else -1)
        fraction = self.speed_fraction()
        values = self.motor.step(now, pulses=self.running, speed_fraction=fraction,
                                 torque_fraction=load_torque(fraction, accelerating) if self.running else 0.0)
        current_ref, dc_ref, heat_ref = self.words.electrical_refs
        self._set_engineering(current_ref, values.current_a)
        self._set_engineering(dc_ref, values.dc_bus_v)
        self._set_engineering(heat_ref, values.heat_sink_c)


def _has(node: DeviceHost, ref: str) -> bool:
    try:
        node.store.catalog.resolve(ref)
    except UnknownParameter:
        return False
    return True
