"""A simulated generic CiA 402 servo: state machine, position/velocity loop, profile ramps, homing, limit switches,
following-error fault, quick-stop deceleration, EMCY on faults.

Built for any profile with 0x6040/0x6041 and no vendor control section (the demo plant's node 7,
``device_profiles/generic-cia402-servo.json``, or an uploaded EDS). It reads only the objects the EDS gives; one it
lacks is left out (no value written, default used).

Units (CiA 402-2): positions in position units = increments x feed / (encoder resolution x gear ratio) (0x608F,
0x6091, 0x6092; 1 unit = 1 increment without them); velocities in rpm when 0x60A9 says rev/min, else position
units per second; accelerations in velocity units per second.

The machine around the motor (not in the EDS): the axis travels between a negative and a positive limit switch
(0x60FD bits 0/1) at ``LIMIT_REVS`` motor revolutions either side of its mechanical zero, a home switch (bit 2)
covers the first half revolution above it, and the encoder gives one index pulse per revolution. ``jam()`` blocks
the load so the following error grows into the fault (0x8611).

Timing: the model steps only while something moves or a state transition is pending; an idle drive costs one
comparison per plant tick.
"""

from __future__ import annotations

import math

from drivebench.errors import UnknownParameter
from drivebench.simulator import homing
from drivebench.simulator.drive402 import STATE_BITS, State402, StateMachine402, command_state
from drivebench.simulator.host import DeviceHost
from drivebench.simulator.store import RawValue

CYCLE_S = 0.002
MAX_STEP_S = 0.02
"""A late tick (loaded machine) integrates at most this much time at once."""
POSITION_LAG_S = 0.008
"""Time constant of the position loop: the actual position follows the demand this closely."""
LIMIT_REVS = 20.0
START_REVS = 5.3
INDEX_AT = 100
"""Index pulse at this many increments past each whole revolution."""
SUPPORTED = (1, 3, 4, 6, 7, 8, 9, 10)
FOLLOWING_ERROR = 0x8611
OVERCURRENT = 0x2310  # CiA 402: continuous over current (device output side)
CURRENT_PER_TORQUE = 1.1
"""0x6078 current actual value per unit of 0x6077 torque actual value (both per mille of rated)."""
TRIP_AFTER_S = 0.05
"""How long the current stays above the trip level before the drive trips."""
RPM_CODE = 0x00B44700

CW_NEW_SET_POINT, CW_IMMEDIATE, CW_RELATIVE, CW_HALT = 0x0010, 0x0020, 0x0040, 0x0100
CW_ENABLE_IP = CW_NEW_SET_POINT  # ip: enable ip mode
SW_VOLTAGE, SW_REMOTE, SW_TARGET_REACHED, SW_LIMIT = 0x0010, 0x0200, 0x0400, 0x0800
SW_ACK, SW_ERROR = 0x1000, 0x2000  # pp: set-point acknowledge / following error; hm: homing attained / error
SW_IP_ACTIVE = SW_ACK  # ip: ip mode active


def _signed(value: RawValue, default: float = 0.0) -> float:
    return float(value) if isinstance(value, (int, float)) else default


class Servo402(StateMachine402):
    def __init__(self, node: DeviceHost) -> None:
        super().__init__(node)
        encoder = self._ratio(0x608F, 4096.0)
        self.increments_per_rev = encoder
        self.per_unit = self._per_unit(encoder)
        self.mech = START_REVS * encoder  # increments from the mechanical zero (between the limit switches)
        self.home = 0.0  # mechanical position of position 0
        self.demand = self.mech
        self.velocity = 0.0  # demand velocity, increments/s
        self.actual_velocity = 0.0
        self.torque = 0.0  # per mille of rated torque: acceleration and friction
        self.target: float | None = None  # profile position: demand target (mechanical increments)
        self.ip_goal: float | None = None  # interpolated position: the last data record (mechanical increments)
        self.ip_speed = 0.0  # ... reached linearly within one interpolation period (increments/s)
        self.machine = homing.Machine(limit=LIMIT_REVS * encoder, cam=(0.0, encoder / 2))
        self.homing: list[homing.Phase] = []
        self.homing_method = 0
        self.homing_done = False
        self.homing_error = False
        self.ack = False
        self.limit_hit = False
        self.soft_limited = False  # held at a software position limit 0x607D (status bit 11)
        self.jammed = False
        self.trip_current: float | None = None
        """Per mille of rated current above which the drive trips (OVERCURRENT; the plant file's
        ``trip_current_permille``); None: it never does."""
        self._error_since: float | None = None
        self._over_since: float | None = None
        self._last: float | None = None
        self._published: dict[tuple[int, int], RawValue] = {}
        self.store.add_write_hook(self.on_write)
        self.reset()

    # --- units ---------------------------------------------------------------------------------------------------
    def _obj(self, index: int, sub: int = 0, default: float = 0.0) -> float:
        return _signed(self.store.get(index, sub), default) if self.store.has(index, sub) else default

    def _ratio(self, index: int, default: float) -> float:
        top, bottom = self._obj(index, 1), self._obj(index, 2)
        return top / bottom if top and bottom else default

    def _per_unit(self, encoder: float) -> float:
        feed = self._ratio(0x6092, 0.0)
        return encoder * self._ratio(0x6091, 1.0) / feed if feed else 1.0

    def _per_velocity_unit(self) -> float:
        """Increments/s of one velocity unit."""
        if int(self._obj(0x60A9)) == RPM_CODE:
            return self.increments_per_rev * self._ratio(0x6091, 1.0) / 60
        return self.per_unit

    def _velocity(self, index: int, sub: int = 0, default: float = 0.0) -> float:
        return self._obj(index, sub, default) * self._per_velocity_unit()

    def _acceleration(self, index: int, default: float) -> float:
        return max(self._velocity(index, 0, default), 1.0)

    def position(self) -> float:
        """Position actual value in position units."""
        return (self.mech - self.home) / self.per_unit

    # --- life cycle ------------------------------------------------------------------------------------------------
    def reset(self) -> None:
        with self._lock:
            self.state = State402.NOT_READY_TO_SWITCH_ON
            self.control_word = int(self._obj(0x6040))
            self.velocity = self.actual_velocity = 0.0
            self.demand = self.mech
            self.target, self.homing, self.ip_goal = None, [], None
            self.fault_code = 0
            self.history = [self.state]
            self._last = None
            self._publish()

    def jam(self, jammed: bool = True) -> None:
        """Block (or free) the load: the actual position stops following the demand."""
        with self._lock:
            self.jammed = jammed
            self._last = None

    def raise_fault(self, code: int) -> None:
        with self._lock:
            if self.state in (State402.FAULT, State402.FAULT_REACTION_ACTIVE):
                return
            self.fault_code = code
            self.homing, self.target = [], None
            self._enter(State402.FAULT_REACTION_ACTIVE)
            if self.store.has(0x603F, 0):
                self.store.set(0x603F, 0, code, notify=False)
        self.node.raise_emcy(code, 0x01 | (0x20 if code >> 12 == 8 else 0))

    # --- inputs ----------------------------------------------------------------------------------------------------
    def on_write(self, index: int, sub: int, raw: RawValue) -> None:
        if index == 0x60C1 and sub == 1 and isinstance(raw, int):
            self._ip_record(raw)
        if sub != 0 or not isinstance(raw, int):
            return
        if index == 0x6040:
            self._on_control_word(raw & 0xFFFF)
        elif index == 0x6060:
            with self._lock:
                if raw in SUPPORTED and self.store.has(0x6061, 0):
                    self.store.set(0x6061, 0, raw, notify=False)
                    self.target, self.homing, self.ip_goal = None, [], None
                    self._publish()
        elif index in (0x607A, 0x60FF, 0x6071):
            self._wake()  # a setpoint may start a move (cyclic modes: every RPDO)

    def _ip_record(self, raw: int) -> None:
        """Linear interpolation (0x60C0 = 0): from where the demand is to the new record within one period."""
        with self._lock:
            self.ip_goal = self.home + raw * self.per_unit
            period = self._obj(0x60C2, 1, 10) * 10 ** self._obj(0x60C2, 2, -3) or CYCLE_S
            self.ip_speed = abs(self.ip_goal - self.demand) / max(period, CYCLE_S)
            self._wake()

    def _interpolated(self, top: float) -> None:
        if self.ip_goal is None or not self.control_word & CW_ENABLE_IP:
            self.velocity = 0.0
            return
        speed = min(self.ip_speed, top)
        self.velocity = math.copysign(speed, self.ip_goal - self.demand) if self.ip_goal != self.demand else 0.0

    def _wake(self) -> None:
        self._idle = False

    def _mode(self) -> int:
        return int(self._obj(0x6061, 0, 1))

    def _on_control_word(self, cw: int) -> None:
        with self._lock:
            previous, self.control_word = self.control_word, cw
            self._wake()
            if self.state is State402.NOT_READY_TO_SWITCH_ON:
                self._enter(State402.SWITCH_ON_DISABLED)
            self._fault_reset(cw, previous)
            target = command_state(self.state, cw)
            if target is not self.state:
                if target is State402.QUICK_STOP_ACTIVE and int(self._obj(0x605A, 0, 2)) == 0:
                    target = State402.SWITCH_ON_DISABLED  # option 0: disable drive function at once
                self._enter(target)
            if self.state is not State402.OPERATION_ENABLED:
                self.target, self.homing, self.ip_goal = None, [], None
                self.ack = False
                self._publish()
                return
            rising = cw & CW_NEW_SET_POINT and not previous & CW_NEW_SET_POINT
            if self._mode() == 1:
                if rising:
                    self._new_set_point(cw)
                elif not cw & CW_NEW_SET_POINT:
                    self.ack = False
            elif self._mode() == 6:
                if rising:
                    self._start_homing()
                elif not cw & CW_NEW_SET_POINT and self.homing:
                    self.homing = []  # homing interrupted
            self._publish()

    def _new_set_point(self, cw: int) -> None:
        target = self._obj(0x607A) * self.per_unit
        base = (self.target if self.target is not None else self.demand) if cw & CW_RELATIVE else self.home
        self.target = base + target
        self.ack = True
        self.homing_done = False

    # --- homing ----------------------------------------------------------------------------------------------------
    def _start_homing(self) -> None:
        method = int(self._obj(0x6098, 0, 35))
        self.homing_done = self.homing_error = False
        self.target = None
        self.homing_method = method
        if method in (35, 37):
            self._homed(self.mech)
            return
        if method not in homing.METHODS:
            self.homing_error = True  # a method this drive does not know: status bit 13, no motion
            return
        self._plan_homing(method)

    def _plan_homing(self, method: int, *, reversed_at_limit: bool = False) -> None:
        fast, slow = self._velocity(0x6099, 1, 600), self._velocity(0x6099, 2, 60)
        self.homing = homing.plan(method, self.demand, self.machine, fast, slow, reversed_at_limit=reversed_at_limit)

    def _homed(self, at: float) -> None:
        offset = self._obj(0x607C) * self.per_unit
        self.home = at - offset  # CiA 402: the home position is the home offset
        self.homing = []
        self.homing_done = True

    def _homing_event(self, before: float, after: float) -> float | None:
        """The mechanical position where the current phase's event happened between two positions, if it did."""
        phase = self.homing[0]
        if phase.edge is not None:
            return self.machine.position(phase.edge) if homing.crossed(self.machine, phase, before, after) else None
        return homing.index_pulse(before, after, self.increments_per_rev, INDEX_AT)

    # --- the cycle -------------------------------------------------------------------------------------------------
    _idle = False

    def tick(self, now: float) -> None:
        if self._idle:
            return
        if self._last is not None and now - self._last < CYCLE_S:
            return
        with self._lock:
            dt = min(now - self._last, MAX_STEP_S) if self._last is not None else CYCLE_S
            self._last = now
            if self.state is State402.NOT_READY_TO_SWITCH_ON:
                self._enter(State402.SWITCH_ON_DISABLED)
            self._step(dt, now)
            self._publish()
            moving = self.velocity or abs(self.demand - self.mech) > 0.5 or self.homing or \
                self.target is not None or self.state in (State402.QUICK_STOP_ACTIVE,
                                                          State402.FAULT_REACTION_ACTIVE)
            self._idle = not moving

    def next_tick(self) -> float | None:
        """When the next cycle is due for the plant's ticker; None while idle (a write clears that and wakes it)."""
        if self._idle:
            return None
        return self._last + CYCLE_S if self._last is not None else 0.0

    def _decelerate(self, rate: float, dt: float) -> None:
        step = rate * dt
        self.velocity = 0.0 if abs(self.velocity) <= step else self.velocity - math.copysign(step, self.velocity)

    def _ramp_to(self, wanted: float, dt: float, accel: float, decel: float) -> None:
        speeding_up = abs(wanted) > abs(self.velocity) and wanted * self.velocity >= 0
        step = (accel if speeding_up else decel) * dt
        delta = wanted - self.velocity
        self.velocity = wanted if abs(delta) <= step else self.velocity + math.copysign(step, delta)

    def _profile_position(self, dt: float, accel: float, decel: float, top: float) -> None:
        if self.target is None:
            self._decelerate(decel, dt)
            return
        remaining = self.target - self.demand
        speed = min(self._velocity(0x6081, 0, 600), top)
        braking = self.velocity ** 2 / (2 * decel)
        wanted = 0.0 if abs(remaining) <= braking + abs(self.velocity) * dt else math.copysign(speed, remaining)
        if wanted == 0.0 and abs(remaining) <= max(abs(self.velocity) * dt, 0.5) and abs(self.velocity) <= decel * dt:
            self.demand, self.velocity = self.target, 0.0
            return
        if wanted == 0.0 and self.velocity * remaining <= 0 and abs(self.velocity) <= decel * dt:
            wanted = math.copysign(min(speed, math.sqrt(2 * decel * abs(remaining))), remaining)
        self._ramp_to(wanted, dt, accel, decel)

    def _homing_step(self, dt: float) -> None:
        if not self.homing:
            self._decelerate(self._acceleration(0x609A, 3000), dt)
            return
        phase, rate = self.homing[0], self._acceleration(0x609A, 3000)
        self._ramp_to(phase.direction * phase.speed, dt, rate, rate)

    def _step(self, dt: float, now: float) -> None:
        accel, decel = self._acceleration(0x6083, 3000), self._acceleration(0x6084, 3000)
        top = self._velocity(0x607F, 0, 3000) or math.inf
        mode = self._mode()
        if self.state in (State402.QUICK_STOP_ACTIVE, State402.FAULT_REACTION_ACTIVE):
            self._decelerate(self._acceleration(0x6085, 20000), dt)
        elif self.state is not State402.OPERATION_ENABLED or self.control_word & CW_HALT:
            self._decelerate(decel, dt)
        elif mode == 1:
            self._profile_position(dt, accel, decel, top)
        elif mode == 6:
            self._homing_step(dt)
        elif mode in (3, 9):
            wanted = max(-top, min(top, self._velocity(0x60FF)))
            if mode == 9:
                self.velocity = wanted
            else:
                self._ramp_to(wanted, dt, accel, decel)
        elif mode == 7:
            self._interpolated(top)
        elif mode == 8:
            goal = self.home + self._obj(0x607A) * self.per_unit
            self.velocity = max(-top, min(top, (goal - self.demand) / dt)) if dt else 0.0
        elif mode in (4, 10):
            torque = self._obj(0x6071)
            self._ramp_to(torque / 1000 * top, dt, accel, decel)  # a load whose speed follows the torque
        before = self.demand
        self._soft_limits(dt, decel, mode)
        self.demand += self.velocity * dt
        if mode == 7 and self.ip_goal is not None and (self.demand - self.ip_goal) * self.velocity > 0:
            self.demand, self.velocity = self.ip_goal, 0.0  # the record reached within the period
        self._limits()
        if mode == 6 and self.homing:
            event = self._homing_event(before, self.demand)
            if event is not None:
                self.homing.pop(0)
                if not self.homing:
                    self._homed(event)
        if not self.jammed:  # velocity feed-forward, the position loop takes out what is left
            error = before - self.mech
            self.mech += (self.demand - before) + error * min(1.0, dt / POSITION_LAG_S)
        actual = self.velocity if not self.jammed else 0.0
        self.torque = (actual - self.actual_velocity) / dt / self._per_velocity_unit() / 10 if dt else 0.0
        self.torque += math.copysign(20.0, actual) if actual else 0.0  # friction
        self.actual_velocity = actual
        self._following_error(now)
        self._overcurrent(now)
        stays = int(self._obj(0x605A, 0, 2)) in (5, 6, 7, 8)  # quick stop option: stay in quick stop active
        if self.velocity == 0 and self.state is State402.QUICK_STOP_ACTIVE and not stays:
            self._enter(State402.SWITCH_ON_DISABLED)  # transition 12
        elif self.velocity == 0 and self.state is State402.FAULT_REACTION_ACTIVE:
            self._enter(State402.FAULT)  # transition 14

    def _clamps(self) -> bool:
        """The drive keeps inside 0x607D itself: its profile says so, or the object it names switches it on."""
        limits = self.node.profile.software_limits
        if limits.drive_clamps:
            return True
        if limits.clamps_ref is None:
            return False
        try:
            return bool(self.store.get_ref(limits.clamps_ref))
        except UnknownParameter:
            return False

    def _soft_bounds(self) -> tuple[float, float] | None:
        """The software position limits 0x607D in mechanical increments (None: none, 0/0, or not clamped here)."""
        if not self.store.has(0x607D, 2) or not self._clamps():
            return None
        low, high = self._obj(0x607D, 1), self._obj(0x607D, 2)
        if low == high == 0:
            return None
        return self.home + low * self.per_unit, self.home + high * self.per_unit

    def _soft_limits(self, dt: float, decel: float, mode: int) -> None:
        """CiA 402 software position limits kept by the drive (not while homing: that sets the reference): a motion
        towards a limit slows with the profile deceleration so that it ends there, and stays there while the
        setpoint still points beyond it; status bit 11 *internal limit active* while the limit holds the motion."""
        self.soft_limited = False
        bounds = self._soft_bounds() if mode != 6 else None
        if bounds is None or not self.velocity:
            return
        sign = 1.0 if self.velocity > 0 else -1.0
        edge = bounds[1] if sign > 0 else bounds[0]
        room = (edge - self.demand) * sign
        allowed = math.sqrt(2 * decel * room) if room > 0 else 0.0
        if abs(self.velocity) * dt >= room:  # would reach or pass the limit within this cycle
            allowed = max(room, 0.0) / dt if dt else 0.0
        if abs(self.velocity) > allowed:
            self.velocity = sign * allowed
            self.soft_limited = True

    def _limits(self) -> None:
        """The limit switches stop a move towards them (status bit 11). Homing runs onto one on purpose when its
        phase seeks that switch; a method that did not seek it turns round there (7 ... 14, 23 ... 30) or ends with
        a homing error (status bit 13)."""
        limit = self.machine.limit
        seeking = self.homing[0].edge if self.homing else None
        self.limit_hit = False
        if self.demand <= -limit and self.velocity < 0 and seeking != "neg_limit":
            self.demand, self.velocity, self.limit_hit = -limit, 0.0, True
        elif self.demand >= limit and self.velocity > 0 and seeking != "pos_limit":
            self.demand, self.velocity, self.limit_hit = limit, 0.0, True
        if self.limit_hit and self.homing:
            if homing.METHODS[self.homing_method].reverses:
                self._plan_homing(self.homing_method, reversed_at_limit=True)
            else:
                self.homing, self.homing_error = [], True
        outwards = self.homing and (seeking, self.homing[0].direction) in (("neg_limit", -1), ("pos_limit", 1))
        if outwards and abs(self.demand) >= limit + self.increments_per_rev:
            self.homing, self.homing_error = [], True  # ran a revolution past the switch: it is broken

    def _overcurrent(self, now: float) -> None:
        """Trip when the current stays above ``trip_current`` for :data:`TRIP_AFTER_S` (an acceleration's spike)."""
        over = self.trip_current is not None and self.state is State402.OPERATION_ENABLED and \
            abs(self.torque * CURRENT_PER_TORQUE) > self.trip_current
        if not over:
            self._over_since = None
        elif self._over_since is None:
            self._over_since = now
        elif now - self._over_since >= TRIP_AFTER_S:
            self._over_since = None
            self.raise_fault(OVERCURRENT)

    def _following_error(self, now: float) -> None:
        window = self._obj(0x6065, 0, 0) * self.per_unit
        if not window or self.state is not State402.OPERATION_ENABLED or abs(self.demand - self.mech) <= window:
            self._error_since = None
            return
        if self._error_since is None:
            self._error_since = now
        elif now - self._error_since >= self._obj(0x6066, 0, 50) / 1000:
            self._error_since = None
            self.raise_fault(FOLLOWING_ERROR)

    # --- outputs ---------------------------------------------------------------------------------------------------
    def _enter(self, state: State402) -> None:
        self._idle = False
        super()._enter(state)

    def inputs(self) -> int:
        word = 0x1 if self.machine.switch_active("neg_limit", self.mech) else 0
        word |= 0x2 if self.machine.switch_active("pos_limit", self.mech) else 0
        word |= 0x4 if self.machine.switch_active("cam_low", self.mech) else 0
        return word

    def status_word(self) -> int:
        word = STATE_BITS[self.state] | SW_REMOTE
        if self.control_word & 0x02 and self.state is not State402.NOT_READY_TO_SWITCH_ON:
            word |= SW_VOLTAGE
        if self.limit_hit or self.soft_limited:
            word |= SW_LIMIT
        if self.state is not State402.OPERATION_ENABLED:
            return word
        mode = self._mode()
        window = max(self._obj(0x6067, 0, 1) * self.per_unit, 1.0)
        settled = self.velocity == 0 and abs(self.demand - self.mech) <= window
        if mode == 1:
            word |= SW_ACK if self.ack else 0
            word |= SW_TARGET_REACHED if (self.target is None or self.demand == self.target) and settled else 0
            word |= SW_ERROR if self._error_since is not None else 0
        elif mode == 6:
            word |= SW_ACK if self.homing_done else 0
            word |= SW_ERROR if self.homing_error else 0
            word |= SW_TARGET_REACHED if (self.homing_done or self.homing_error or not self.homing) and settled else 0
        elif mode == 7:
            word |= SW_IP_ACTIVE if self.control_word & CW_ENABLE_IP else 0
            word |= SW_TARGET_REACHED if self.ip_goal is not None and self.demand == self.ip_goal and settled else 0
        elif mode == 3:
            wanted = self._velocity(0x60FF)
            word |= SW_TARGET_REACHED if abs(self.velocity - wanted) < 1 else 0
            word |= SW_ACK if self.velocity == 0 else 0  # pv: speed = 0
        return word

    def _put(self, index: int, value: int) -> None:
        if self.store.has(index, 0) and self._published.get((index, 0)) != value:
            self._published[(index, 0)] = value
            self.store.set(index, 0, value)

    def _publish(self) -> None:
        per_velocity = self._per_velocity_unit()
        torque = round(max(-3000.0, min(3000.0, self.torque)))
        self._put(0x6041, self.status_word())
        self._put(0x6064, round(self.position()))
        self._put(0x6063, round(self.mech - self.home))
        self._put(0x6062, round((self.demand - self.home) / self.per_unit))
        self._put(0x606C, round(self.actual_velocity / per_velocity))
        self._put(0x60F4, round((self.demand - self.mech) / self.per_unit))
        self._put(0x6077, torque if self.state is State402.OPERATION_ENABLED else 0)
        self._put(0x6078, round(torque * CURRENT_PER_TORQUE) if self.state is State402.OPERATION_ENABLED else 0)
        self._put(0x6079, 48000 - abs(torque) * 2)
        self._put(0x60FD, self.inputs())
