"""CiA 402 (IEC 61800-7-201, CiA 402-2) as data: the standard drive control of any device whose object
dictionary has 0x6040/0x6041 and whose profile brings no ``control`` section of its own.

Standard names only: the state machine, control/status word bits, modes of operation (0x6060/0x6502), homing
methods (0x6098), the error codes of 0x603F, the SI units of 0x60A8/0x60A9 (CiA 303-2 notation index and prefix),
and the actual values the panel shows.
"""

from __future__ import annotations

from drivebench.device.control import (
    ActualSpec,
    Arrow,
    Command,
    CommandBits,
    ControlSection,
    JogPlan,
    Setpoint,
    StateBox,
)
from drivebench.device.profile import Profile

STATE_MASKS = (  # (mask, value, state) on status word bits 0, 1, 2, 3, 5, 6
    (0x4F, 0x00, "not_ready"), (0x4F, 0x40, "switch_on_disabled"), (0x6F, 0x21, "ready"),
    (0x6F, 0x23, "switched_on"), (0x6F, 0x27, "operation_enabled"), (0x6F, 0x07, "quick_stop_active"),
    (0x4F, 0x0F, "fault_reaction_active"), (0x4F, 0x08, "fault"),
)
CONTROL_BITS = {
    0: "Switch on", 1: "Enable voltage", 2: "Quick stop (0 = active)", 3: "Enable operation",
    4: "Operation mode specific (pp: new set-point; hm: homing operation start)",
    5: "Operation mode specific (pp: change set immediately)", 6: "Operation mode specific (pp: absolute / relative)",
    7: "Fault reset", 8: "Halt", 9: "Operation mode specific (pp: change on set-point)", 10: "Reserved",
    11: "Manufacturer specific", 12: "Manufacturer specific", 13: "Manufacturer specific",
    14: "Manufacturer specific", 15: "Manufacturer specific",
}
STATUS_BITS = {
    0: "Ready to switch on", 1: "Switched on", 2: "Operation enabled", 3: "Fault", 4: "Voltage enabled",
    5: "Quick stop (0 = active)", 6: "Switch on disabled", 7: "Warning", 8: "Manufacturer specific", 9: "Remote",
    10: "Target reached", 11: "Internal limit active",
    12: "Operation mode specific (pp: set-point acknowledge; pv: speed = 0; hm: homing attained)",
    13: "Operation mode specific (pp: following error; hm: homing error)", 14: "Manufacturer specific",
    15: "Manufacturer specific",
}
STATES = [
    StateBox(key="not_ready", label="Not ready to switch on", col=0, row=0),
    StateBox(key="switch_on_disabled", label="Switch on disabled", col=0, row=1),
    StateBox(key="ready", label="Ready to switch on", col=0, row=2),
    StateBox(key="switched_on", label="Switched on", col=0, row=3),
    StateBox(key="operation_enabled", label="Operation enabled", col=0, row=4, enabled=True),
    StateBox(key="quick_stop_active", label="Quick stop active", col=1, row=4, enabled=True),
    StateBox(key="fault_reaction_active", label="Fault reaction active", col=2, row=0, fault=True),
    StateBox(key="fault", label="Fault", col=2, row=1, fault=True),
]
ARROWS = [
    Arrow(from_state="not_ready", to_state="switch_on_disabled", label="1"),
    Arrow(from_state="switch_on_disabled", to_state="ready", label="2 Shutdown"),
    Arrow(from_state="ready", to_state="switched_on", label="3 Switch on"),
    Arrow(from_state="switched_on", to_state="operation_enabled", label="4 Enable"),
    Arrow(from_state="operation_enabled", to_state="switched_on", label="5 Disable op."),
    Arrow(from_state="switched_on", to_state="ready", label="6 Shutdown"),
    Arrow(from_state="ready", to_state="switch_on_disabled", label="7 QS / disable voltage"),
    Arrow(from_state="operation_enabled", to_state="quick_stop_active", label="11 Quick stop"),
    Arrow(from_state="quick_stop_active", to_state="switch_on_disabled", label="12"),
    Arrow(from_state="fault_reaction_active", to_state="fault", label="14"),
    Arrow(from_state="fault", to_state="switch_on_disabled", label="15 Fault reset"),
]
COMMANDS = {
    Command.SHUTDOWN: CommandBits(clear=0x8F, set=0x06), Command.SWITCH_ON: CommandBits(clear=0x8F, set=0x07),
    Command.ENABLE_OPERATION: CommandBits(clear=0x8F, set=0x0F),
    Command.DISABLE_OPERATION: CommandBits(clear=0x8F, set=0x07),
    Command.QUICK_STOP: CommandBits(clear=0x86, set=0x02), Command.DISABLE_VOLTAGE: CommandBits(clear=0x82, set=0x00),
    Command.FAULT_RESET: CommandBits(clear=0x00, set=0x80, edge=0x80),
}

# --- modes of operation ---------------------------------------------------------------------------------------
MODE_NAMES = {
    1: "Profile position", 2: "Velocity", 3: "Profile velocity", 4: "Profile torque", 6: "Homing",
    7: "Interpolated position", 8: "Cyclic synchronous position", 9: "Cyclic synchronous velocity",
    10: "Cyclic synchronous torque",
}
MODE_BITS = {1: 0, 2: 1, 3: 2, 4: 3, 6: 5, 7: 6, 8: 7, 9: 8, 10: 9}
"""0x6502 supported drive modes: mode -> bit."""
MODE_OBJECTS = {1: (0x607A, 0x6081), 2: (0x6042,), 3: (0x60FF,), 4: (0x6071,), 6: (0x6098,), 7: (0x60C1, 0x60C2),
                8: (0x607A, 0x60C2), 9: (0x60FF, 0x60C2), 10: (0x6071, 0x60C2)}
"""The objects a mode needs in the object dictionary (modes found from the EDS when there is no 0x6502)."""
CYCLIC_MODES = (7, 8, 9, 10)
"""Modes whose setpoint travels in an RPDO every SYNC (7: the interpolation data record 0x60C1.1)."""


def mode_label(mode: int) -> str:
    """A mode's name; a negative one is the manufacturer's (never shown as "null")."""
    if mode < 0:
        return f"manufacturer-specific (\u2212{-mode})"
    if mode == 0:
        return "no mode assigned"
    return MODE_NAMES.get(mode, f"reserved ({mode})")


def modes_from_6502(value: int) -> list[int]:
    return [mode for mode, bit in MODE_BITS.items() if value >> bit & 1]


_CAM_METHODS = {  # 7 ... 14: a home switch active over part of the travel; (first move, edge, index side)
    7: ("positive", "lower", "below"), 8: ("positive", "lower", "above"), 9: ("positive", "upper", "below"),
    10: ("positive", "upper", "above"), 11: ("negative", "upper", "above"), 12: ("negative", "upper", "below"),
    13: ("negative", "lower", "above"), 14: ("negative", "lower", "below"),
}
HOMING_METHODS = {
    1: "Negative limit switch and index pulse", 2: "Positive limit switch and index pulse",
    3: "Positive home switch and index pulse (index below the switch edge)",
    4: "Positive home switch and index pulse (index above the switch edge)",
    5: "Negative home switch and index pulse (index above the switch edge)",
    6: "Negative home switch and index pulse (index below the switch edge)",
    **{method: f"Home switch and index pulse: start {way}, reverse at the {way} limit switch, index {side} the "
               f"switch's {edge} edge" for method, (way, edge, side) in _CAM_METHODS.items()},
    17: "Negative limit switch", 18: "Positive limit switch",
    19: "Positive home switch (its edge, reached from above)", 20: "Positive home switch (its edge, reached from "
    "below)", 21: "Negative home switch (its edge, reached from below)",
    22: "Negative home switch (its edge, reached from above)",
    **{method + 16: f"Home switch: start {way}, reverse at the {way} limit switch, the switch's {edge} edge "
                    f"reached from {'above' if side == 'below' else 'below'}"
       for method, (way, edge, side) in _CAM_METHODS.items()},
    33: "Index pulse in negative direction", 34: "Index pulse in positive direction",
    35: "Current position (no movement)", 37: "Current position (no movement, CiA 402-2)",
}


def homing_label(method: int) -> str:
    if method < 0:
        return f"manufacturer-specific (\u2212{-method})"
    return HOMING_METHODS.get(method, f"reserved ({method})")


# --- error codes (0x603F) --------------------------------------------------------------------------------------
ERROR_CODES = {
    0x0000: "No error", 0x1000: "Generic error", 0x2110: "Short circuit / earth leakage (input)",
    0x2220: "Continuous over current (device input)", 0x2300: "Current, device output side",
    0x2310: "Continuous over current", 0x2320: "Short circuit / earth leakage (motor side)",
    0x3100: "Mains voltage", 0x3210: "DC link over-voltage", 0x3220: "DC link under-voltage",
    0x4210: "Excess temperature device", 0x4310: "Excess temperature drive", 0x5112: "Supply low voltage",
    0x5400: "Power section", 0x6010: "Software reset (watchdog)", 0x6320: "Parameter error",
    0x7121: "Motor blocked", 0x7300: "Sensor", 0x7305: "Incremental sensor 1 fault", 0x7500: "Communication",
    0x8110: "CAN overrun", 0x8120: "CAN in error passive mode", 0x8130: "Life guard or heartbeat error",
    0x8140: "Recovered from bus-off", 0x8400: "Velocity speed controller", 0x8500: "Position controller",
    0x8611: "Following error", 0x8612: "Reference limit", 0x9000: "External error",
}
ERROR_CLASSES = {0x1: "Generic error", 0x2: "Current", 0x3: "Voltage", 0x4: "Temperature", 0x5: "Device hardware",
                 0x6: "Device software", 0x7: "Additional modules", 0x8: "Monitoring", 0x9: "External error",
                 0xF: "Additional functions"}


def error_text(code: int) -> str:
    if code in ERROR_CODES:
        return ERROR_CODES[code]
    if code >> 8 == 0xFF:
        return "Manufacturer-specific error"
    return f"{ERROR_CLASSES.get(code >> 12, 'Unknown error class')} (0x{code:04X})"


# --- digital inputs (0x60FD) -----------------------------------------------------------------------------------
INPUT_BITS = {0: "Negative limit switch", 1: "Positive limit switch", 2: "Home switch", 3: "Interlock"}

# --- SI units (0x60A8 / 0x60A9): byte 3 prefix, byte 2 unit, byte 1 denominator (CiA 303-2) ------------------
SI_PREFIX = {0x00: "", 0x03: "k", 0xFF: "d", 0xFE: "c", 0xFD: "m", 0xFA: "µ", 0xF7: "n"}
SI_UNIT = {0x00: "", 0x01: "m", 0x03: "s", 0x10: "rad", 0x41: "°", 0x47: "min", 0x48: "h", 0xB4: "rev",
           0xB5: "inc"}
SPECIAL_UNITS = {"rev/min": "rpm"}


def si_unit(code: int) -> str | None:
    """``0x00410000`` -> "°", ``0x00B44700`` -> "rpm", ``0xFD010300`` -> "mm/s"; None for a code it cannot name."""
    prefix, unit, denominator = code >> 24 & 0xFF, code >> 16 & 0xFF, code >> 8 & 0xFF
    if prefix not in SI_PREFIX or unit not in SI_UNIT or (denominator and denominator not in SI_UNIT):
        return None
    text = SI_PREFIX[prefix] + SI_UNIT[unit]
    if denominator:
        text += "/" + SI_UNIT[denominator]
    return SPECIAL_UNITS.get(text, text) or None


# --- the generic section ----------------------------------------------------------------------------------------
ACTUALS = [  # (label, object, unit where CiA 402 fixes it; position and velocity units come from the drive)
    ("Position", "0x6064", None), ("Velocity", "0x606C", None), ("Torque", "0x6077", "‰ of rated torque"),
    ("Current", "0x6078", "‰ of rated current"), ("DC link voltage", "0x6079", "mV"),
    ("Following error", "0x60F4", None), ("Position demand", "0x6062", None),
]
UNIT_KIND = {"0x607A": "position", "0x60FF": "velocity", "0x6081": "velocity", "0x6099.1": "velocity",
             "0x6099.2": "velocity", "0x607C": "position", "0x607D.1": "position", "0x607D.2": "position",
             "0x607F": "velocity", "0x60F4": "position", "0x6064": "position", "0x606C": "velocity",
             "0x6062": "position", "0x6065": "position", "0x60C1.1": "position"}


def has_drive_words(profile: Profile) -> bool:
    found = {(obj.index, obj.subindex) for obj in profile.objects}
    return (0x6040, 0) in found and (0x6041, 0) in found


def listed_modes(profile: Profile) -> list[int]:
    """Modes whose objects the EDS lists (used when the device has no 0x6502)."""
    indices = {obj.index for obj in profile.objects}
    return [mode for mode, needs in MODE_OBJECTS.items() if all(index in indices for index in needs)]


def generic_section(profile: Profile) -> ControlSection:
    """The standard CiA 402 drive control of ``profile`` (standard names only, modes and values by its objects)."""
    indices = {obj.index for obj in profile.objects}
    modes = listed_modes(profile)
    setpoints = [Setpoint(ref=ref, unit=unit, modes=[mode]) for mode, ref, unit in (
        (1, "0x607A", "position"), (3, "0x60FF", "velocity"), (4, "0x6071", "‰"), (2, "0x6042", "rpm"),
        (7, "0x60C1.1", "position"), (8, "0x607A", "position"), (9, "0x60FF", "velocity"), (10, "0x6071", "‰"))
        if int(ref.split(".")[0], 16) in indices]
    return ControlSection(
        key="cia402-generic", state_machine="cia402", title="CiA 402 drive state machine",
        note="Standard CiA 402 drive control (no vendor profile): bit names, modes and units as CiA 402-2 defines "
             "them and this device's object dictionary lists them.",
        control_word="0x6040", status_word="0x6041", control_bits=CONTROL_BITS, status_bits=STATUS_BITS,
        states=STATES, arrows=ARROWS, commands=COMMANDS, setpoints=setpoints,
        actual_values=[ActualSpec(label=label, ref=ref, unit=unit) for label, ref, unit in ACTUALS
                       if int(ref, 16) in indices],
        actual_kinds=[], jog=JogPlan(method="profile_velocity" if 3 in modes else "setpoint",
                                     text="Jog: a profile-velocity move (the panel switches to mode 3, 0x60FF) at "
                                          "{value:g} {unit} while the button is held and the keep-alive runs.",
                                     why="the device lists no profile velocity mode (0x60FF)"),
        modes={mode: MODE_NAMES[mode] for mode in modes},
        mode_refused="0x6061 shows {shown} after writing 0x6060 = {mode}: the drive did not take the mode.",
        modes_help="Mode {mode} is not among this device's supported modes (0x6502 or its object dictionary).",
        simulation="cia402_servo")
