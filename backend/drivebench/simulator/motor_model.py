"""Electrical and thermal actual values of a simulated inverter and its motor: current, DC-bus voltage, heat sink.

Not from a manual: a small plausible model so the control panel has values that move with the drive state.

* Current: 0 A while the pulses are inhibited; with the pulses on the magnetising current (40 % of rated) plus
  the torque-producing part, ``I = I_rated * sqrt(0.4^2 + (torque / rated torque)^2)``.
* Load torque of the demo machine (a fan behind some friction): ``0.05 + 0.75 * (speed / max speed)^2`` of the
  rated torque, plus 30 % while it accelerates.
* DC bus on 400 V mains: charged to the mains peak (565 V) at rest, sagging with the power drawn (down to 540 V),
  with 1 V of ripple so a plot shows it live.
* Heat sink: first-order towards ``start + 25 K * (I / I_rated)^2 + 2 K`` (pulses on) with a 90 s time constant;
  with the pulses off it cools back to its start value (the manuals' read example, 43 degC) and lands on it exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MAINS_V = 400.0
MAGNETISING = 0.4
FRICTION, FAN = 0.05, 0.75
ACCEL_TORQUE = 0.3
HEAT_K, SWITCHING_K, TAU_S = 25.0, 2.0, 90.0
UPDATE_S = 0.1  # the values change 10 times a second (a plot polls 4/s), not in every 4 or 8 ms cycle


@dataclass(frozen=True)
class Actuals:
    current_a: float
    dc_bus_v: float
    heat_sink_c: float


def load_torque(speed_fraction: float, accelerating: int = 0) -> float:
    """Torque (fraction of rated, signed like the speed) the demo machine needs at this speed."""
    sign = 1.0 if speed_fraction >= 0 else -1.0
    steady = (FRICTION if speed_fraction else 0.0) + FAN * speed_fraction * speed_fraction
    return sign * steady + ACCEL_TORQUE * accelerating


class MotorModel:
    def __init__(self, rated_current_a: float, heat_sink_c: float) -> None:
        self.rated_current_a = rated_current_a
        self.start_c = heat_sink_c
        self.heat_sink_c = heat_sink_c
        self._last: float | None = None
        self._values: tuple[bool, Actuals] | None = None

    def settled(self) -> bool:
        """At rest: pulses off and the heat sink back at its start value (nothing changes until the drive runs)."""
        return self._values is not None and not self._values[0] and self.heat_sink_c == self.start_c

    def step(self, now: float, *, pulses: bool, speed_fraction: float, torque_fraction: float) -> Actuals:
        """Advance to ``now`` (seconds, monotonic) and return the actual values."""
        if self._values is not None and self._last is not None and self._values[0] == pulses \
                and now - self._last < UPDATE_S:
            return self._values[1]  # pulses switched: at once (0 A the moment they are inhibited)
        dt = 0.0 if self._last is None else max(0.0, now - self._last)
        self._last = now
        load = min(abs(torque_fraction), 2.0)
        current = self.rated_current_a * math.hypot(MAGNETISING, load) if pulses else 0.0
        power = min(1.5, load * abs(speed_fraction)) if pulses else 0.0
        ripple = math.sin(now * 2 * math.pi * 0.4) if pulses else 0.0
        dc_bus = MAINS_V * math.sqrt(2) - 20.0 * power + ripple
        target = self.start_c + (HEAT_K * (current / self.rated_current_a) ** 2 + SWITCHING_K if pulses else 0.0)
        self.heat_sink_c += (target - self.heat_sink_c) * (1 - math.exp(-dt / TAU_S))
        if abs(target - self.heat_sink_c) < 0.05:
            self.heat_sink_c = target
        values = Actuals(round(current, 2), round(max(540.0, dc_bus), 1), round(self.heat_sink_c, 1))
        self._values = (pulses, values)
        return values
