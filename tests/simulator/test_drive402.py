"""CiA 402 device control of the simulated MICROMASTER 440 (node 3 of the demo plant), against its manual.

The first-commissioning sequences of the MICROMASTER CANopen manual (ch. 5.7 velocity mode, 5.8 profile torque
mode) are replayed telegram by telegram as printed; the answers are the printed ones. Test-only deviation: the
ramp-up time P1120 is 1 s instead of 10 s so the run to 1000 rpm ends within the test's deadline.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.scaling import to_raw
from drivebench.simulator.drive402 import STATE_BITS, Drive402, State402
from drivebench.simulator.plant import Plant, PlantFile
from tests.conftest import DEMO_PLANT, fresh_channel
from tests.simulator.wire_script import WireScript

MM = 3

PREPARE = [  # steps 1...6 of ch. 5.7 (velocity) - step 6 differs in the torque chapter
    ("2b f8 27 00 00 00 00 00", "60 f8 27 00"),  # P2040 = 0
    ("2b bc 22 00 06 00 00 00", "60 bc 22 00"),  # P0700 = 6
    ("2b e8 23 00 06 00 00 00", "60 e8 23 00"),  # P1000 = 6
    ("2b cf 22 00 00 00 00 00", "60 cf 22 00"),  # P0719 = 0
    ("22 dd 25 00 0c 00 2b 08", "60 dd 25 00"),  # P1501 = r2091.12 (expedited, size not indicated)
]
TRANSMISSION_TYPES = [(f"2f {low:02x} {high:02x} 02 ff 00 00 00", f"60 {low:02x} {high:02x} 02")
                      for high, low in ((0x14, 0x00), (0x14, 0x04), (0x14, 0x05), (0x18, 0x00), (0x18, 0x04),
                                        (0x18, 0x05))]


def _mapping(index: int, second: str) -> list[tuple[str, str]]:
    low, high = index & 0xFF, index >> 8
    first = "10 00 40 60" if high == 0x16 else "10 00 41 60"
    head = f"{low:02x} {high:02x}"
    return [(f"2f {head} 00 00 00 00 00", f"60 {head} 00"), (f"23 {head} 01 {first}", f"60 {head} 01"),
            (f"23 {head} 02 {second}", f"60 {head} 02"), (f"2f {head} 00 02 00 00 00", f"60 {head} 00")]


VELOCITY = [*PREPARE, ("2b 14 25 00 00 00 00 00", "60 14 25 00"), *TRANSMISSION_TYPES,
            *_mapping(0x1604, "10 00 42 60"), *_mapping(0x1A04, "10 00 44 60"),
            *_mapping(0x1605, "08 00 60 60"), *_mapping(0x1A05, "08 00 61 60")]
TORQUE = [*PREPARE, ("2b 14 25 00 16 00 00 00", "60 14 25 00"), ("22 df 25 00 04 00 02 08", "60 df 25 00"),
          ("2f 60 60 00 04 00 00 00", "60 60 60 00"), *TRANSMISSION_TYPES,
          *_mapping(0x1604, "10 00 71 60"), *_mapping(0x1A04, "10 00 77 60"),
          *_mapping(0x1605, "08 00 60 60"), *_mapping(0x1A05, "08 00 61 60")]


@pytest.fixture
def script(wire: can.BusABC) -> WireScript:
    return WireScript(wire)


def _replay(script: WireScript, steps: list[tuple[str, str]]) -> None:
    for request, answer in steps:
        response = script.sdo(MM, request)
        assert response[:4].hex(" ") == answer, f"{request} answered {response.hex(' ')}"


def _fast_ramp(plant: Plant) -> None:
    plant.nodes[MM].store.set_ref("P1120", 1.0)


def test_velocity_mode_first_commissioning_as_printed(plant: Plant, script: WireScript) -> None:
    _fast_ramp(plant)
    _replay(script, VELOCITY)
    script.send(0x000, "01 03")
    script.send(0x203, "06 00")
    script.status_word(0x183, 0xFE31)
    script.send(0x203, "07 00")
    assert script.status_word(0x183, 0xFE33)
    assert script.expect(0x383, lambda data: data == bytes.fromhex("33 fe 02"))  # TPDO6: SW + modes display 2
    script.send(0x203, "0f 00")
    script.status_word(0x183, 0xFE37)  # "the drive is now in the operational state"
    script.send(0x303, "7f 00 e8 03")  # CW 0x7F + 0x6042 = 1000 rpm
    script.status_word(0x183, 0xFA37)  # ramping: target reached (bit 10) = 0
    script.status_word(0x183, 0xFE37)  # target reached
    assert plant.nodes[MM].store.get(0x6044, 0) == 1000
    assert plant.nodes[MM].drive is not None and plant.nodes[MM].drive.state is State402.OPERATION_ENABLED


def test_profile_torque_mode_first_commissioning_as_printed(plant: Plant, script: WireScript) -> None:
    _replay(script, TORQUE)
    assert script.sdo(MM, "40 61 60 00 00 00 00 00")[:5] == bytes.fromhex("4f 61 60 00 04")  # 0x6061 = 4
    script.send(0x000, "01 03")
    script.send(0x203, "06 00")
    assert script.expect(0x383, lambda data: data == bytes.fromhex("31 fe 04"))  # ready, modes display 4
    script.send(0x203, "07 00")
    script.status_word(0x183, 0xFE33)
    script.send(0x203, "0f 00")
    script.status_word(0x183, 0xFE37)
    script.send(0x303, "7f 00 c8 00")  # target torque 200 permille
    torque = script.expect(0x283, lambda data: int.from_bytes(data[2:4], "little", signed=True) >= 150)
    assert torque[:2] in (bytes.fromhex("37 fe"), bytes.fromhex("37 fa"))
    assert plant.nodes[MM].store.get(0x6061, 0) == 4


def test_control_word_is_ignored_until_p0700_selects_can(plant: Plant, script: WireScript) -> None:
    """Manual ch. 3.3: the control word works only with P0700 = 6 (the Siemens default is 2, terminals)."""
    drive = plant.nodes[MM].drive
    assert drive is not None
    _poll_until(script, lambda: drive.state is State402.SWITCH_ON_DISABLED)
    script.sdo(MM, "2b 40 60 00 06 00 00 00")
    assert drive.state is State402.SWITCH_ON_DISABLED
    script.sdo(MM, "2b bc 22 00 06 00 00 00")
    script.sdo(MM, "2b 40 60 00 06 00 00 00")
    assert drive.state is State402.READY_TO_SWITCH_ON


def _poll_until(script: WireScript, done: Callable[[], bool], timeout_s: float = 8.0) -> None:
    """Read the status word by SDO (as a master polls) until ``done``."""
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "condition not met in time"
        script.sdo(MM, "40 41 60 00 00 00 00 00")


def _sdo_cw(script: WireScript, word: int) -> None:
    assert script.sdo(MM, f"2b 40 60 00 {word & 0xFF:02x} {word >> 8:02x} 00 00")[0] == 0x60


def _sw(script: WireScript) -> int:
    return int.from_bytes(script.sdo(MM, "40 41 60 00 00 00 00 00")[4:6], "little")


def test_every_state_shows_its_table_3_18_bits(plant: Plant, script: WireScript) -> None:
    """Shutdown, switch on, enable, disable operation, quick stop, fault, fault reset: 0x6041 per table 3-18."""
    _fast_ramp(plant)
    node = plant.nodes[MM]
    drive = node.drive
    assert drive is not None
    for step in PREPARE:
        script.sdo(MM, step[0])
    script.sdo(MM, "2b 42 60 00 f4 01 00 00")  # 0x6042 = 500 rpm
    _poll_until(script, lambda: drive.state is State402.SWITCH_ON_DISABLED)  # after the power-up self-test
    seen = {State402.SWITCH_ON_DISABLED: _sw(script)}
    for word, state in ((0x06, State402.READY_TO_SWITCH_ON), (0x07, State402.SWITCHED_ON),
                        (0x0F, State402.OPERATION_ENABLED), (0x07, State402.SWITCHED_ON),
                        (0x7F, State402.OPERATION_ENABLED), (0x0B, State402.QUICK_STOP_ACTIVE)):
        if state is State402.QUICK_STOP_ACTIVE:
            # A drive at standstill leaves quick stop active within one cycle: stop a turning motor instead.
            _poll_until(script, lambda: drive.speed_rpm >= 100)
        _sdo_cw(script, word)
        seen[state] = _sw(script)
        assert drive.state is state, f"CW 0x{word:02X}"
    drive.raise_fault(7)  # F0007 motor overtemperature
    seen[State402.FAULT_REACTION_ACTIVE] = drive.status_word()
    _poll_until(script, lambda: drive.state is State402.FAULT)
    seen[State402.FAULT] = _sw(script)
    assert drive.state is State402.FAULT
    _sdo_cw(script, 0x80)  # fault reset: rising edge of bit 7
    assert drive.state is State402.SWITCH_ON_DISABLED
    for state, word in seen.items():
        mask = 0x006F if state in (State402.READY_TO_SWITCH_ON, State402.SWITCHED_ON, State402.OPERATION_ENABLED,
                                   State402.QUICK_STOP_ACTIVE) else 0x004F
        assert word & mask == STATE_BITS[state] & mask, f"{state.value}: 0x{word:04X}"


def test_quick_stop_ends_in_switch_on_disabled_once_stopped(plant: Plant, script: WireScript) -> None:
    _fast_ramp(plant)
    drive = plant.nodes[MM].drive
    assert drive is not None
    for step in PREPARE:
        script.sdo(MM, step[0])
    script.sdo(MM, "2b 42 60 00 f4 01 00 00")  # 0x6042 = 500 rpm
    for word in (0x06, 0x07, 0x7F):
        _sdo_cw(script, word)
    _poll_until(script, lambda: drive.speed_rpm >= 100)
    _sdo_cw(script, 0x7B)  # quick stop (bit 2 = 0)
    assert drive.state is State402.QUICK_STOP_ACTIVE
    _poll_until(script, lambda: drive.state is State402.SWITCH_ON_DISABLED)
    assert drive.state is State402.SWITCH_ON_DISABLED and drive.speed_rpm == 0
    assert State402.QUICK_STOP_ACTIVE in drive.history


def test_reverse_bit_turns_the_motor_left(plant: Plant, script: WireScript) -> None:
    """Table 3-15: control word bit 11 = MM "Reverse"; status bit 14 "motor runs direction right" then clears."""
    _fast_ramp(plant)
    drive = plant.nodes[MM].drive
    assert drive is not None
    for step in PREPARE:
        script.sdo(MM, step[0])
    script.sdo(MM, "2b 42 60 00 2c 01 00 00")  # 0x6042 = 300 rpm
    for word in (0x06, 0x07, 0x087F):
        _sdo_cw(script, word)
    _poll_until(script, lambda: drive.speed_rpm <= -300)
    assert not _sw(script) & 0x4000
    assert plant.nodes[MM].store.get(0x6044, 0) == -300


def test_quick_commissioning_gating_on_the_wire(plant: Plant, script: WireScript) -> None:
    """Issue 30: motor data are written only while P0010 = 1; otherwise the drive answers the CANopen manual's
    abort 0x08000022 ("the task cannot be executed due to the operating state", table of ch. 3.2.4). P3900 = 3
    ends quick commissioning: P0010 reads 0 again, and the motor data stay locked. The rated current P0305 is
    the motor model's."""
    store = plant.nodes[MM].store
    refused = script.sdo(MM, "2b 30 21 00 90 01 00 00")  # P0304 (0x2130) = 400 V while P0010 = 0
    assert refused.hex(" ") == "80 30 21 00 22 00 00 08" and store.get_ref("P0304") == 0
    assert script.sdo(MM, "2b 0a 20 00 01 00 00 00")[:4].hex(" ") == "60 0a 20 00"  # P0010 = 1
    assert script.sdo(MM, "2b 30 21 00 90 01 00 00")[:4].hex(" ") == "60 30 21 00"
    assert script.sdo(MM, "23 31 21 00 33 33 73 40")[:4].hex(" ") == "60 31 21 00"  # P0305 = 3.8 A (REAL32)
    drive = plant.nodes[MM].drive
    assert drive is not None and drive.motor.rated_current_a == pytest.approx(3.8)
    assert script.sdo(MM, "2b 3c 2f 00 03 00 00 00")[:4].hex(" ") == "60 3c 2f 00"  # P3900 = 3
    assert script.sdo(MM, "40 0a 20 00 00 00 00 00")[:6].hex(" ") == "4b 0a 20 00 00 00"  # P0010 = 0 again
    assert script.sdo(MM, "2b 30 21 00 2c 01 00 00").hex(" ") == "80 30 21 00 22 00 00 08"
    assert store.get_ref("P0304") == 400


def test_velocity_ramps_in_the_ramp_up_time_when_the_cycles_come_late(registry: ProfileRegistry) -> None:
    """On a loaded machine the plant's cycles come late (here every 100 ms rather than every 8 ms): the drive still
    ramps at its ramp-up rate per second (150 rpm/s: 300 rpm after 2 s), not per cycle. The plant is not started:
    the test ticks the drive at a loaded machine's pace."""
    plant = Plant(PlantFile.load(DEMO_PLANT), registry.get, bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    drive, store = plant.nodes[MM].drive, plant.nodes[MM].store
    assert isinstance(drive, Drive402) and drive._rate_rpm_s(False) == 150
    now = 1000.0
    drive.tick(now)
    for ref in ("P0700", "P1000"):  # command source and setpoint from CAN
        store.set_ref(ref, to_raw(store.catalog.resolve(ref).entry, 6))
    store.set(0x6042, 0, 300)
    for control_word in (0x06, 0x07, 0x0F, 0x7F):  # shutdown, switch on, enable operation, ramp released
        store.set(0x6040, 0, control_word)
        now += 0.1
        drive.tick(now)
    assert drive.state is State402.OPERATION_ENABLED
    for _ in range(9):
        now += 0.1
        drive.tick(now)
    assert store.get(0x6044, 0) == pytest.approx(150, abs=20)  # 1 s of ramp
    for _ in range(11):
        now += 0.1
        drive.tick(now)
    assert store.get(0x6044, 0) == 300
