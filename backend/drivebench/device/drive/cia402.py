"""CiA 402 (IEC 61800-7-201, CiA 402-2) as data: the standard drive control of any device whose object
dictionary has 0x6040/0x6041 and whose profile brings no ``control`` section of its own.

Standard names only: the state machine, control/status word bits, modes of operation (0x6060/0x6502), homing
methods (0x6098), the error codes of 0x603F, the SI units of 0x60A8/0x60A9 (CiA 303-2 notation index and prefix),
and the actual values the panel shows. The names are English data marked N_(); :func:`shown` gives them in the
reader's language (a vendor profile's own texts, the manual's wording, stay as printed).
"""

from __future__ import annotations

from drivebench.device.drive.control import (
    DRIVEBENCH_TEXTS,
    ActualSpec,
    Arrow,
    Command,
    CommandBits,
    ControlSection,
    JogPlan,
    Setpoint,
    StateBox,
)
from drivebench.device.profiles.profile import Profile
from drivebench.i18n import DEFAULT, N_, _, current

# --- the objects, as refs, by their CiA 402-2 names (services/control names them only so) --------------------------
ERROR_CODE = "0x603F"
CONTROL_WORD, STATUS_WORD = "0x6040", "0x6041"
QUICK_STOP_OPTION_CODE = "0x605A"
MODES_OF_OPERATION, MODES_OF_OPERATION_DISPLAY = "0x6060", "0x6061"
POSITION_ACTUAL_VALUE, VELOCITY_ACTUAL_VALUE = "0x6064", "0x606C"
TARGET_TORQUE, MAX_TORQUE = "0x6071", "0x6072"
TARGET_POSITION, HOME_OFFSET = "0x607A", "0x607C"
MIN_POSITION_LIMIT, MAX_POSITION_LIMIT = "0x607D.1", "0x607D.2"
"""The software position limits (0/0: none)."""
MAX_PROFILE_VELOCITY, PROFILE_VELOCITY = "0x607F", "0x6081"
PROFILE_ACCELERATION, PROFILE_DECELERATION, QUICK_STOP_DECELERATION = "0x6083", "0x6084", "0x6085"
POSITION_ENCODER_RESOLUTION, GEAR_RATIO, FEED_CONSTANT = "0x608F", "0x6091", "0x6092"
HOMING_METHOD, HOMING_ACCELERATION = "0x6098", "0x609A"
SPEED_SEARCH_FOR_SWITCH, SPEED_SEARCH_FOR_ZERO = "0x6099.1", "0x6099.2"
SI_UNIT_POSITION, SI_UNIT_VELOCITY = "0x60A8", "0x60A9"
INTERPOLATION_DATA_RECORD = "0x60C1.1"
INTERPOLATION_PERIOD_VALUE, INTERPOLATION_PERIOD_INDEX = "0x60C2.1", "0x60C2.2"
"""Interpolation time period: value x 10^index s."""
SUPPORTED_HOMING_METHODS = "0x60E3"
"""An array: sub 0 the count, sub n a method."""
DIGITAL_INPUTS, TARGET_VELOCITY = "0x60FD", "0x60FF"
SUPPORTED_DRIVE_MODES = "0x6502"


def sub(ref: str, subindex: int) -> str:
    """``ref`` at ``subindex`` (``sub(SUPPORTED_HOMING_METHODS, 2)`` = ``0x60E3.2``)."""
    return f"{ref}.{subindex}"

STATE_MASKS = (  # (mask, value, state) on status word bits 0, 1, 2, 3, 5, 6
    (0x4F, 0x00, "not_ready"), (0x4F, 0x40, "switch_on_disabled"), (0x6F, 0x21, "ready"),
    (0x6F, 0x23, "switched_on"), (0x6F, 0x27, "operation_enabled"), (0x6F, 0x07, "quick_stop_active"),
    (0x4F, 0x0F, "fault_reaction_active"), (0x4F, 0x08, "fault"),
)
MODE_SPECIFIC, MANUFACTURER = N_("Operation mode specific"), N_("Manufacturer specific")
CONTROL_BITS = {
    0: N_("Switch on"), 1: N_("Enable voltage"), 2: N_("Quick stop (0 = active)"), 3: N_("Enable operation"),
    4: N_("Operation mode specific (pp: new set-point; hm: homing operation start)"),
    5: N_("Operation mode specific (pp: change set immediately)"),
    6: N_("Operation mode specific (pp: absolute / relative)"), 7: N_("Fault reset"), 8: N_("Halt"),
    9: N_("Operation mode specific (pp: change on set-point)"), 10: N_("Reserved"),
    11: MANUFACTURER, 12: MANUFACTURER, 13: MANUFACTURER, 14: MANUFACTURER, 15: MANUFACTURER,
}
STATUS_BITS = {
    0: N_("Ready to switch on"), 1: N_("Switched on"), 2: N_("Operation enabled"), 3: N_("Fault"),
    4: N_("Voltage enabled"), 5: N_("Quick stop (0 = active)"), 6: N_("Switch on disabled"), 7: N_("Warning"),
    8: MANUFACTURER, 9: N_("Remote"), 10: N_("Target reached"), 11: N_("Internal limit active"),
    12: N_("Operation mode specific (pp: set-point acknowledge; pv: speed = 0; hm: homing attained)"),
    13: N_("Operation mode specific (pp: following error; hm: homing error)"), 14: MANUFACTURER, 15: MANUFACTURER,
}
STATES = [
    StateBox(key="not_ready", label=N_("Not ready to switch on"), col=0, row=0),
    StateBox(key="switch_on_disabled", label=N_("Switch on disabled"), col=0, row=1),
    StateBox(key="ready", label=N_("Ready to switch on"), col=0, row=2),
    StateBox(key="switched_on", label=N_("Switched on"), col=0, row=3),
    StateBox(key="operation_enabled", label=N_("Operation enabled"), col=0, row=4, enabled=True),
    StateBox(key="quick_stop_active", label=N_("Quick stop active"), col=1, row=4, enabled=True),
    StateBox(key="fault_reaction_active", label=N_("Fault reaction active"), col=2, row=0, fault=True),
    StateBox(key="fault", label=N_("Fault"), col=2, row=1, fault=True),
]
ARROWS = [
    Arrow(from_state="not_ready", to_state="switch_on_disabled", label="1"),
    Arrow(from_state="switch_on_disabled", to_state="ready", label=N_("2 Shutdown")),
    Arrow(from_state="ready", to_state="switched_on", label=N_("3 Switch on")),
    Arrow(from_state="switched_on", to_state="operation_enabled", label=N_("4 Enable")),
    Arrow(from_state="operation_enabled", to_state="switched_on", label=N_("5 Disable op.")),
    Arrow(from_state="switched_on", to_state="ready", label=N_("6 Shutdown")),
    Arrow(from_state="ready", to_state="switch_on_disabled", label=N_("7 QS / disable voltage")),
    Arrow(from_state="operation_enabled", to_state="quick_stop_active", label=N_("11 Quick stop")),
    Arrow(from_state="quick_stop_active", to_state="switch_on_disabled", label="12"),
    Arrow(from_state="fault_reaction_active", to_state="fault", label="14"),
    Arrow(from_state="fault", to_state="switch_on_disabled", label=N_("15 Fault reset")),
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
    1: N_("Profile position"), 2: N_("Velocity"), 3: N_("Profile velocity"), 4: N_("Profile torque"), 6: N_("Homing"),
    7: N_("Interpolated position"), 8: N_("Cyclic synchronous position"), 9: N_("Cyclic synchronous velocity"),
    10: N_("Cyclic synchronous torque"),
}
MODE_BITS = {1: 0, 2: 1, 3: 2, 4: 3, 6: 5, 7: 6, 8: 7, 9: 8, 10: 9}
"""0x6502 supported drive modes: mode -> bit."""
MODE_OBJECTS = {1: (0x607A, 0x6081), 2: (0x6042,), 3: (0x60FF,), 4: (0x6071,), 6: (0x6098,), 7: (0x60C1, 0x60C2),
                8: (0x607A, 0x60C2), 9: (0x60FF, 0x60C2), 10: (0x6071, 0x60C2)}
"""The objects a mode needs in the object dictionary (modes found from the EDS when there is no 0x6502)."""
CYCLIC_MODES = (7, 8, 9, 10)
"""Modes whose setpoint travels in an RPDO every SYNC (7: the interpolation data record 0x60C1.1)."""
CYCLIC_TARGETS = {7: INTERPOLATION_DATA_RECORD, 8: TARGET_POSITION, 9: TARGET_VELOCITY, 10: TARGET_TORQUE}
"""The setpoint a cyclic mode's RPDO carries each SYNC."""


def mode_label(mode: int) -> str:
    """A mode's name in the reader's language; a negative one is the manufacturer's (never shown as "null")."""
    if mode < 0:
        return _("manufacturer-specific (\u2212{number})").format(number=-mode)
    if mode == 0:
        return _("no mode assigned")
    return _(MODE_NAMES[mode]) if mode in MODE_NAMES else _("reserved ({number})").format(number=mode)


def modes_from_6502(value: int) -> list[int]:
    return [mode for mode, bit in MODE_BITS.items() if value >> bit & 1]


_CAM_METHODS = {  # 7 ... 14: a home switch active over part of the travel; (first move, edge, index side)
    7: ("positive", "lower", "below"), 8: ("positive", "lower", "above"), 9: ("positive", "upper", "below"),
    10: ("positive", "upper", "above"), 11: ("negative", "upper", "above"), 12: ("negative", "upper", "below"),
    13: ("negative", "lower", "above"), 14: ("negative", "lower", "below"),
}
CAM_WORDS = (N_("positive"), N_("negative"), N_("lower"), N_("upper"), N_("below"), N_("above"))
CAM_INDEX = N_("Home switch and index pulse: start {way}, reverse at the {way} limit switch, index {side} the "
               "switch's {edge} edge")
CAM_EDGE = N_("Home switch: start {way}, reverse at the {way} limit switch, the switch's {edge} edge reached from "
              "{side}")
HOMING_METHODS = {
    1: N_("Negative limit switch and index pulse"), 2: N_("Positive limit switch and index pulse"),
    3: N_("Positive home switch and index pulse (index below the switch edge)"),
    4: N_("Positive home switch and index pulse (index above the switch edge)"),
    5: N_("Negative home switch and index pulse (index above the switch edge)"),
    6: N_("Negative home switch and index pulse (index below the switch edge)"),
    **{method: CAM_INDEX for method in _CAM_METHODS},
    17: N_("Negative limit switch"), 18: N_("Positive limit switch"),
    19: N_("Positive home switch (its edge, reached from above)"),
    20: N_("Positive home switch (its edge, reached from below)"),
    21: N_("Negative home switch (its edge, reached from below)"),
    22: N_("Negative home switch (its edge, reached from above)"),
    **{method + 16: CAM_EDGE for method in _CAM_METHODS},
    33: N_("Index pulse in negative direction"), 34: N_("Index pulse in positive direction"),
    35: N_("Current position (no movement)"), 37: N_("Current position (no movement, CiA 402-2)"),
}
"""Method -> its name; the cam methods 7...14 and 23...30 name their move, edge and side (:func:`homing_label`)."""


def homing_label(method: int) -> str:
    """A homing method's name in the reader's language."""
    if method < 0:
        return _("manufacturer-specific (\u2212{number})").format(number=-method)
    if method not in HOMING_METHODS:
        return _("reserved ({number})").format(number=method)
    cam = _CAM_METHODS.get(method if method <= 14 else method - 16)
    if cam is None:
        return _(HOMING_METHODS[method])
    way, edge, side = cam
    if method > 14:  # reached from the other side than the index of the same cam method
        side = "above" if side == "below" else "below"
    return _(HOMING_METHODS[method]).format(way=_(way), edge=_(edge), side=_(side))


# --- error codes (0x603F) --------------------------------------------------------------------------------------
ERROR_CODES = {
    0x0000: N_("No error"), 0x1000: N_("Generic error"), 0x2110: N_("Short circuit / earth leakage (input)"),
    0x2220: N_("Continuous over current (device input)"), 0x2300: N_("Current, device output side"),
    0x2310: N_("Continuous over current"), 0x2320: N_("Short circuit / earth leakage (motor side)"),
    0x3100: N_("Mains voltage"), 0x3210: N_("DC link over-voltage"), 0x3220: N_("DC link under-voltage"),
    0x4210: N_("Excess temperature device"), 0x4310: N_("Excess temperature drive"),
    0x5112: N_("Supply low voltage"), 0x5400: N_("Power section"), 0x6010: N_("Software reset (watchdog)"),
    0x6320: N_("Parameter error"), 0x7121: N_("Motor blocked"), 0x7300: N_("Sensor"),
    0x7305: N_("Incremental sensor 1 fault"), 0x7500: N_("Communication"), 0x8110: N_("CAN overrun"),
    0x8120: N_("CAN in error passive mode"), 0x8130: N_("Life guard or heartbeat error"),
    0x8140: N_("Recovered from bus-off"), 0x8400: N_("Velocity speed controller"), 0x8500: N_("Position controller"),
    0x8611: N_("Following error"), 0x8612: N_("Reference limit"), 0x9000: N_("External error"),
}
ERROR_CLASSES = {0x1: N_("Generic error"), 0x2: N_("Current"), 0x3: N_("Voltage"), 0x4: N_("Temperature"),
                 0x5: N_("Device hardware"), 0x6: N_("Device software"), 0x7: N_("Additional modules"),
                 0x8: N_("Monitoring"), 0x9: N_("External error"), 0xF: N_("Additional functions")}

def error_text(code: int) -> str:
    """The CiA 402 name of an error code in the reader's language."""
    if code in ERROR_CODES:
        return _(ERROR_CODES[code])
    if code >> 8 == 0xFF:
        return _("Manufacturer-specific error")
    return f"{_(ERROR_CLASSES.get(code >> 12, N_('Unknown error class')))} (0x{code:04X})"


# --- digital inputs (0x60FD) -----------------------------------------------------------------------------------
INPUT_BITS = {0: N_("Negative limit switch"), 1: N_("Positive limit switch"), 2: N_("Home switch"),
              3: N_("Interlock")}

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
    (N_("Position"), "0x6064", None), (N_("Velocity"), "0x606C", None),
    (N_("Torque"), "0x6077", N_("‰ of rated torque")), (N_("Current"), "0x6078", N_("‰ of rated current")),
    (N_("DC link voltage"), "0x6079", "mV"), (N_("Following error"), "0x60F4", None),
    (N_("Position demand"), "0x6062", None),
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


TITLE = N_("CiA 402 drive state machine")
NOTE = N_("Standard CiA 402 drive control (no vendor profile): bit names, modes and units as CiA 402-2 defines them "
          "and this device's object dictionary lists them.")
JOG_TEXT = N_("Jog: a profile-velocity move (the panel switches to mode 3, 0x60FF) at the jog speed set here, while "
              "the button is held and the keep-alive runs; each press shows the speed it will send.")
JOG_WHY = N_("the device lists no profile velocity mode (0x60FF)")
MODE_REFUSED = N_("0x6061 shows {shown} after writing 0x6060 = {mode}: the drive did not take the mode.")
MODES_HELP = N_("Mode {mode} is not among this device's supported modes (0x6502 or its object dictionary).")


def generic_section(profile: Profile) -> ControlSection:
    """The standard CiA 402 drive control of ``profile`` (standard names only, modes and values by its objects)."""
    indices = {obj.index for obj in profile.objects}
    modes = listed_modes(profile)
    setpoints = [Setpoint(ref=ref, unit=unit, modes=[mode]) for mode, ref, unit in (
        (1, "0x607A", "position"), (3, "0x60FF", "velocity"), (4, "0x6071", "‰"), (2, "0x6042", "rpm"),
        (7, "0x60C1.1", "position"), (8, "0x607A", "position"), (9, "0x60FF", "velocity"), (10, "0x6071", "‰"))
        if int(ref.split(".")[0], 16) in indices]
    return ControlSection(
        key="cia402-generic", state_machine="cia402", title=TITLE, note=NOTE,
        control_word="0x6040", status_word="0x6041", control_bits=CONTROL_BITS, status_bits=STATUS_BITS,
        states=STATES, arrows=ARROWS, commands=COMMANDS, setpoints=setpoints,
        actual_values=[ActualSpec(label=label, ref=ref, unit=unit) for label, ref, unit in ACTUALS
                       if int(ref, 16) in indices],
        actual_kinds=[], jog=JogPlan(method="profile_velocity" if 3 in modes else "setpoint", text=JOG_TEXT,
                                     why=JOG_WHY),
        modes={mode: MODE_NAMES[mode] for mode in modes}, mode_refused=MODE_REFUSED, modes_help=MODES_HELP,
        simulation="cia402_servo")


STANDARD_TEXTS = frozenset({
    *CONTROL_BITS.values(), *STATUS_BITS.values(), *(box.label for box in STATES), *(arrow.label for arrow in ARROWS),
    *MODE_NAMES.values(), *INPUT_BITS.values(), *(text for label, _ref, unit in ACTUALS for text in (label, unit)
                                                   if text), TITLE, NOTE, JOG_TEXT, JOG_WHY, MODE_REFUSED, MODES_HELP,
    *DRIVEBENCH_TEXTS})


OWN_MSGID = {"Remote": N_("Remote (status word bit 9: the control word is processed)")}
"""Standard names whose English is also another text of the UI (the header's Remote page): translated by a msgid of
their own."""


def shown(text: str) -> str:
    """A text of a control section in the reader's language when it is one of the standard's (or DriveBench's own
    default); a vendor profile's own text (its manual's wording) as it is."""
    if text not in STANDARD_TEXTS:
        return text
    return _(OWN_MSGID[text]) if text in OWN_MSGID and current() != DEFAULT else _(text)
