"""The simulated inverter's electrical and thermal values (simulator/motor_model.py), on a synthetic clock."""

from __future__ import annotations

import pytest

from drivebench.simulator.motor_model import MotorModel, load_torque


def test_no_current_with_the_pulses_inhibited() -> None:
    model = MotorModel(rated_current_a=2.4, heat_sink_c=43.0)
    values = model.step(0.0, pulses=False, speed_fraction=0.5, torque_fraction=0.5)  # coasting after CINH
    assert values.current_a == 0
    assert values.dc_bus_v == pytest.approx(565.7, abs=0.05)  # charged to the peak of 400 V mains
    assert values.heat_sink_c == 43.0


def test_current_rises_with_speed_and_torque() -> None:
    currents = []
    for step, fraction in enumerate((0.0, 0.25, 0.5, 1.0)):
        model = MotorModel(rated_current_a=2.4, heat_sink_c=43.0)
        currents.append(model.step(step, pulses=True, speed_fraction=fraction,
                                   torque_fraction=load_torque(fraction)).current_a)
    assert currents[0] == pytest.approx(0.4 * 2.4)  # magnetising current at standstill
    assert currents == sorted(currents) and len(set(currents)) == 4
    assert load_torque(-0.5) == -load_torque(0.5) and load_torque(0.5, accelerating=1) > load_torque(0.5)


def test_dc_bus_stays_within_540_and_566_volts() -> None:
    model = MotorModel(rated_current_a=2.4, heat_sink_c=43.0)
    volts = [model.step(t / 10, pulses=True, speed_fraction=1.0, torque_fraction=2.0).dc_bus_v for t in range(50)]
    assert all(540 <= v <= 566 for v in volts) and min(volts) < 550  # sags under full load


def test_heat_sink_drifts_slowly_and_cools_back_exactly() -> None:
    model = MotorModel(rated_current_a=2.4, heat_sink_c=43.0)
    after_10s = [model.step(t / 10, pulses=True, speed_fraction=1.0, torque_fraction=1.0).heat_sink_c
                 for t in range(101)][-1]
    assert 43.5 < after_10s < 48  # a 90 s time constant: a few kelvin in 10 s, not a jump
    for t in range(1000, 1020):
        model.step(t, pulses=True, speed_fraction=1.0, torque_fraction=1.0)
    hot = model.heat_sink_c
    assert 65 < hot <= 43 + 25 * (0.4**2 + 1) + 2
    for t in range(2000, 3000, 10):
        model.step(t, pulses=False, speed_fraction=0.0, torque_fraction=0.0)
    assert model.heat_sink_c == 43.0  # the manuals' read example (C0061 / C00061 = 43 degC) holds at rest again
