"""Actual values of the control panel (current, DC-bus voltage, torque, heat sink) read through the real SDO path
from the simulated demo plant: node 3 MICROMASTER 440, 5 8400 motec, 12 8200 vector + EMF2178IB.

The drives are switched with plain parameter writes (control words), not the panel's command path, so these tests
look only at the values: 0 A with the pulses inhibited, current rising with the speed, the DC bus of 400 V mains."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import pytest

from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_control
from drivebench.services.control.drive_control import ActualValue
from drivebench.services.params import parameters
from tests.services.conftest import set_up

T = TypeVar("T")
MM, MOTEC, VECTOR = 3, 5, 12


class Bench:
    def __init__(self, runner: asyncio.Runner, session: Session) -> None:
        self.runner, self.session = runner, session

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self.runner.run(coro)

    def actuals(self, node_id: int) -> dict[str, ActualValue]:
        values = self.run(drive_control.read_actuals(self.session, self.session.node(node_id)))
        return {value.ref: value for value in values}

    def write(self, node_id: int, ref: str, value: float) -> None:
        self.run(set_up(self.session, node_id, ref, value, check=False, verify=False))

    def until(self, node_id: int, ref: str, done: Callable[[float], bool], timeout_s: float = 10.0) -> float:
        deadline = time.monotonic() + timeout_s
        while True:
            value = self.actuals(node_id)[ref].value
            if value is not None and done(value):
                return value
            assert time.monotonic() < deadline, f"node {node_id} {ref} stays {value}"
            self.run(asyncio.sleep(0.05))


@pytest.fixture
def bench(plant_session: tuple[asyncio.Runner, Session]) -> Bench:
    return Bench(*plant_session)


@pytest.mark.parametrize(("node_id", "current", "dc_bus"), [(MM, "r0027", "r0026"), (MOTEC, "C00054", "C00053"),
                                                            (VECTOR, "C0054", "C0053")])
def test_every_demo_drive_plots_current_and_dc_bus(bench: Bench, node_id: int, current: str, dc_bus: str) -> None:
    node = bench.session.node(node_id)
    assert "Current" not in drive_control.missing_actuals(node)
    assert "DC-bus voltage" not in drive_control.missing_actuals(node)
    values = bench.actuals(node_id)
    assert (values[current].label, values[current].unit) == ("Current", "A")
    assert (values[dc_bus].label, values[dc_bus].unit) == ("DC-bus voltage", "V")
    assert values[current].value == 0  # at rest: pulses inhibited
    assert 540 <= (values[dc_bus].value or 0) <= 566  # 400 V mains: charged to the peak, 565.7 V


def test_scaling_on_the_wire(bench: Bench) -> None:
    """FIX32 x 10000 (EMF2178IB), factor 1 (8400 V), REAL32 (MICROMASTER): the raw telegram value and the shown one."""
    for node_id, ref in ((VECTOR, "C0053"), (MOTEC, "C00053"), (MM, "r0026")):  # the model's first values are in
        bench.until(node_id, ref, lambda volts: volts > 565)  # (before them: the profile default, 560 V)
    vector = bench.run(parameters.read(bench.session, VECTOR, "C0053"))
    assert (vector.index, vector.raw, vector.value, vector.unit) == (0x5FCA, 5657000, 565.7, "V")
    motec = bench.run(parameters.read(bench.session, MOTEC, "C00053"))
    assert (motec.index, motec.raw, motec.value, motec.unit) == (0x5FCA, 566, 566, "V")
    micromaster = bench.run(parameters.read(bench.session, MM, "r0026"))
    assert micromaster.index == 0x201A and micromaster.unit == "V"
    assert micromaster.value == pytest.approx(565.7, abs=0.01)
    heat = bench.run(parameters.read(bench.session, VECTOR, "C0061"))
    assert (heat.raw, heat.value) == (430000, 43)  # the manual's read example still holds at rest


def test_sources_are_named_per_value(bench: Bench) -> None:
    sources = {value.ref: value.source or "" for node in (MM, MOTEC, VECTOR) for value in bench.actuals(node).values()}
    assert sources["r0027"].startswith("r0027 = 0x201B.0 (REAL32)")
    assert "MICROMASTER 440 parameter list" in sources["r0027"]
    assert sources["C0054"].startswith("C0054 = 0x5FC9.0 (INTEGER32, value = raw / 10000)")
    assert "8200 vector code table" in sources["C0054"]
    assert sources["C00054"].startswith("C00054 = 0x5FC9.0 (UNSIGNED16, value = raw / 10)")
    assert "ASSUMED" in sources["C00054"]
    assert "EMF2178IB" in sources["C0061"]  # from the profile's own manual
    assert sources["C1823/2"].startswith("C1823/2 = 0x58E0.2") and "Hz = raw / 50" in sources["C1823/2"]


def test_missing_values_say_why(bench: Bench) -> None:
    assert drive_control.missing_actuals(bench.session.node(MM)) == []
    assert drive_control.missing_actuals(bench.session.node(VECTOR)) == ["Torque"]
    assert "no actual-torque code" in drive_control.missing_why(bench.session.node(VECTOR))
    motec = bench.session.node(MOTEC)
    assert drive_control.missing_actuals(motec) == ["Torque"]
    assert "C00056" in drive_control.missing_why(motec)


def test_micromaster_current_follows_the_drive_state(bench: Bench) -> None:
    bench.write(MM, "P0700", 6)
    bench.write(MM, "P1000", 6)
    for word in (0x06, 0x07, 0x0F):  # shutdown, switch on, enable operation
        bench.write(MM, "0x6040", word)
    magnetising = bench.until(MM, "r0027", lambda amps: amps > 0)  # pulses on at standstill
    bench.write(MM, "0x6042", 600)
    bench.write(MM, "0x6040", 0x7F)
    bench.until(MM, "0x6044", lambda rpm: rpm == 600, timeout_s=30)
    running = bench.until(MM, "r0027", lambda amps: amps > magnetising)
    values = bench.actuals(MM)
    assert (values["r0080"].value or 0) > 0 and values["r0080"].unit == "Nm"
    assert 540 <= (values["r0026"].value or 0) <= 566 and running < 2 * 1.9
    bench.write(MM, "0x6040", 0x06)  # shutdown (OFF1): down the ramp (P1121 10 s for 1500 rpm), then pulses off
    bench.until(MM, "r0027", lambda amps: amps == 0, timeout_s=30)
    assert bench.actuals(MM)["0x6044"].value == 0


def test_lenze_current_follows_the_drive_state(bench: Bench) -> None:
    bench.write(MOTEC, "C00866/2", 0x2000)  # 50 % of C00011
    bench.write(MOTEC, "C00866/1", 0x0009)  # switch on + enable
    bench.until(MOTEC, "C00868/2", lambda rpm: rpm >= 740)
    assert bench.until(MOTEC, "C00054", lambda amps: amps > 0) > 0
    bench.write(MOTEC, "C00866/1", 0x0100)  # controller inhibit
    bench.until(MOTEC, "C00054", lambda amps: amps == 0)

    bench.write(VECTOR, "C0135", 0x0200)  # CINH
    bench.write(VECTOR, "C0001", 3)
    bench.write(VECTOR, "C1822/2", 1250)  # 25 Hz
    bench.write(VECTOR, "C0135", 0x0000)
    assert bench.until(VECTOR, "C0054", lambda amps: amps > 0) > 0
    bench.write(VECTOR, "C0135", 0x0200)
    bench.until(VECTOR, "C0054", lambda amps: amps == 0)
