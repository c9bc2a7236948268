"""Lenze device control of the simulated 8200 vector + EMF2178IB (node 12) and 8400 motec (node 5).

EMF2178IB manual ch. 6.5 / 9.3.1: C0001 = 3 (index 0x5FFE, value 30000) lets the process channel overwrite the
control word C0135; bits 3 QSP, 9 CINH, 10 TRIP-SET, 11 TRIP-RESET (rising edge); status word C0150 bits 8...11 the
device status (3 operation inhibited, 6 operation enabled, 8 fault active). Everything is sent as SDO telegrams.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.lenze_control import (
    OPERATION_ENABLED,
    OPERATION_ENABLED_AIF,
    OPERATION_INHIBITED,
    WordControl,
)
from drivebench.simulator.plant import Plant, PlantFile
from tests.conftest import DEMO_PLANT, fresh_channel
from tests.simulator.wire_script import WireScript

VECTOR, MOTEC = 12, 5
C0001, C0135, C0150, C1822, C1823 = 0x5FFE, 0x5F78, 0x5F69, 0x58E1, 0x58E0
C00866, C00868 = 0x5FFF - 866, 0x5FFF - 868


@pytest.fixture
def script(wire: can.BusABC) -> WireScript:
    return WireScript(wire)


def _write(script: WireScript, node: int, index: int, sub: int, value: int, size: int) -> None:
    command = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    data = (value & (1 << 8 * size) - 1).to_bytes(size, "little").ljust(4, b"\0")
    request = bytes([command, index & 0xFF, index >> 8, sub]) + data
    answer = script.sdo(node, request.hex(" "))
    assert answer[0] == 0x60, f"write 0x{index:04X}.{sub} aborted: {answer.hex(' ')}"


def _read16(script: WireScript, node: int, index: int, sub: int = 0) -> int:
    answer = script.sdo(node, f"40 {index & 0xFF:02x} {index >> 8:02x} {sub:02x} 00 00 00 00")
    return int.from_bytes(answer[4:6], "little")


def _until(script: WireScript, node: int, index: int, sub: int, done: Callable[[int], bool],
           timeout_s: float = 8.0) -> int:
    deadline = time.monotonic() + timeout_s
    while not done(word := _read16(script, node, index, sub)):
        assert time.monotonic() < deadline, f"0x{index:04X}.{sub} stays 0x{word:04X}"
    return word


def _device_status(word: int) -> int:
    return word >> 8 & 0x0F


def test_8200_vector_minimal_enable_sequence(plant: Plant, script: WireScript) -> None:
    """CINH set, C0001 = 3, CINH cleared -> operation enabled; the setpoint runs up; QSP brings it to 0."""
    _until(script, VECTOR, C0150, 0, lambda word: _device_status(word) == OPERATION_INHIBITED)
    _write(script, VECTOR, C0135, 0, 0x0200, 2)  # CINH
    _write(script, VECTOR, C0001, 0, 30000, 4)  # C0001 = 3 (x 10000)
    word = _read16(script, VECTOR, C0150)
    assert _device_status(word) == OPERATION_INHIBITED and word & 0x0080  # DCTRL1-CINH
    _write(script, VECTOR, C1822, 2, 1250, 2)  # AIF-IN.W1 = 25 Hz (24000 = 480 Hz)
    _write(script, VECTOR, C0135, 0, 0x0000, 2)  # controller enable
    word = _until(script, VECTOR, C0150, 0, lambda w: _device_status(w) == OPERATION_ENABLED_AIF)
    assert word & 0x8000 and not word & 0x0080  # DCTRL1-RDY, no CINH
    _until(script, VECTOR, C1823, 2, lambda actual: actual == 1250)
    _write(script, VECTOR, C0135, 0, 0x0008, 2)  # QSP
    _until(script, VECTOR, C1823, 2, lambda actual: actual == 0)
    assert _read16(script, VECTOR, C0150) & 0x0040  # DCTRL1-NOUT=0


def test_8200_vector_trip_set_and_trip_reset(plant: Plant, script: WireScript) -> None:
    _write(script, VECTOR, C0001, 0, 30000, 4)
    _write(script, VECTOR, C0135, 0, 0x0400, 2)  # TRIP-SET: external fault
    word = _until(script, VECTOR, C0150, 0, lambda w: _device_status(w) == 8)
    assert not word & 0x8000  # not ready
    _write(script, VECTOR, C0135, 0, 0x0000, 2)
    assert _device_status(_read16(script, VECTOR, C0150)) == 8, "only the rising edge of TRIP-RESET resets"
    _write(script, VECTOR, C0135, 0, 0x0800, 2)  # TRIP-RESET edge 0 -> 1
    assert _device_status(_read16(script, VECTOR, C0150)) in (OPERATION_INHIBITED, OPERATION_ENABLED_AIF)


def test_8400_motec_can1_in_control_word(plant: Plant, script: WireScript) -> None:
    """CAN1_IN word 1 (C00866/1) = wCtrl: SwitchOn + EnableOperation -> device state 5 in CAN1_OUT word 1."""
    _write(script, MOTEC, C00866, 2, 0x2000, 2)  # 50 % of the reference speed
    _write(script, MOTEC, C00866, 1, 0x0009, 2)  # SwitchOn + EnableOperation (bit 2 SetQuickStop = 0)
    _until(script, MOTEC, C00868, 1, lambda word: _device_status(word) == OPERATION_ENABLED)
    _until(script, MOTEC, C00868, 2, lambda actual: actual == 0x2000)
    _write(script, MOTEC, C00866, 1, 0x0100, 2)  # controller inhibit
    word = _until(script, MOTEC, C00868, 1, lambda w: w & 0x0080 != 0)
    assert word & 0x0002  # pulse inhibit


def test_8200_vector_jog_bits_select_c0037(plant: Plant, script: WireScript) -> None:
    """EMF2178IB ch. 9.3.1.1: control word bits 1/0 = 01 -> NSET1-JOG1 (C0037) instead of the setpoint."""
    plant.nodes[VECTOR].store.set_ref("C0037", 100000)  # 10 Hz (raw, x 10000)
    _write(script, VECTOR, C0001, 0, 30000, 4)
    _write(script, VECTOR, C0135, 0, 0x0001, 2)  # JOG1, controller enabled
    _until(script, VECTOR, C1823, 2, lambda actual: actual == 500)  # 10 Hz x 50
    _write(script, VECTOR, C0135, 0, 0x0000, 2)  # back to the setpoint (0)
    _until(script, VECTOR, C1823, 2, lambda actual: actual == 0)
    plant.nodes[VECTOR].store.set_ref("C0007", 520000)  # C0007 = 52 > 51: bits 0/1 freely configurable
    _write(script, VECTOR, C1822, 2, 250, 2)  # setpoint 5 Hz
    _write(script, VECTOR, C0135, 0, 0x0001, 2)  # bit 0 no longer selects JOG1 (10 Hz): the setpoint runs
    _until(script, VECTOR, C1823, 2, lambda actual: actual == 250)


def test_8200_vector_ramps_in_its_acceleration_time_when_the_cycles_come_late(registry: ProfileRegistry) -> None:
    """On a loaded machine the plant's cycles come late (here every 100 ms rather than every 4 ms): the drive still
    ramps at C0011 fmax / C0012 acceleration time per second (50 Hz in 5 s: 25 Hz after 2.5 s), not per cycle.
    The plant is not started: the test ticks the drive at a loaded machine's pace."""
    plant = Plant(PlantFile.load(DEMO_PLANT), registry.get, bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    drive, store = plant.nodes[VECTOR].drive, plant.nodes[VECTOR].store
    assert isinstance(drive, WordControl) and drive.ramp_per_s() == 500  # raw words/s: 24000 = 480 Hz
    now = 1000.0
    drive.tick(now)
    for index, sub, raw in ((C0135, 0, 0x0200), (C0001, 0, 30000), (C1822, 2, 1250), (C0135, 0, 0x0000)):
        store.set(index, sub, raw)  # CINH, C0001 = 3, AIF-IN.W1 = 25 Hz, controller enable (as on the wire)
    assert drive.device_state == OPERATION_ENABLED_AIF
    for _ in range(12):
        now += 0.1
        drive.tick(now)
    assert store.get(C1823, 2) == pytest.approx(600, abs=60)  # 12 Hz after 1.2 s
    for _ in range(14):
        now += 0.1
        drive.tick(now)
    assert store.get(C1823, 2) == 1250
