"""Device control words of each drive family: where they live, what each bit is called, state from status word.

* CiA 402 (MICROMASTER 4, manual ch. 3.3): 0x6040 / 0x6041; commands per table 3-16, states per table 3-18 with the
  CiA 402 masks (bits 0, 1, 2, 3, 5, 6). The manual calls status bit 4 "Voltage disabled" (MM OFF2 active) but every
  trace frame sets it with the voltage enabled, as CiA 402 "voltage enabled" does: the panel follows CiA 402.
* EMF2178IB (8200 vector / 93XX, manual ch. 9.3.1): control word C0135 (AIF-CTRL), status word C0150 (AIF-STAT),
  bits 3 QSP, 9 CINH, 10 TRIP-SET, 11 TRIP-RESET; status bits 8...11 the device status.
* 8400 motec: CAN1_IN word 1 (C00866/1, "wCtrl") and CAN1_OUT word 1 (C00868/1). The CANopen manual names only
  "wCtrl"; the bit names are those of the 8400 network control word (LA_NCtrl) as the simulator implements them -
  an assumption, flagged in the UI.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum

from drivebench.device.catalog import Catalog
from drivebench.errors import UnknownParameter


class Command(StrEnum):
    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch_on"
    ENABLE_OPERATION = "enable_operation"
    DISABLE_OPERATION = "disable_operation"
    QUICK_STOP = "quick_stop"
    DISABLE_VOLTAGE = "disable_voltage"
    FAULT_RESET = "fault_reset"


MOVING = {Command.ENABLE_OPERATION, Command.FAULT_RESET}
"""Commands after which the motor may turn (fault reset too: with C0142 = 1 a Lenze drive restarts by itself)."""

COMMAND_LABELS = {
    Command.SHUTDOWN: "Shutdown", Command.SWITCH_ON: "Switch on", Command.ENABLE_OPERATION: "Enable operation",
    Command.DISABLE_OPERATION: "Disable operation", Command.QUICK_STOP: "Quick stop",
    Command.DISABLE_VOLTAGE: "Disable voltage", Command.FAULT_RESET: "Fault reset",
}


@dataclass(frozen=True)
class StateBox:
    """A state of the drawn state machine: its name, where it is drawn (grid column, row), when it is 'on'."""

    key: str
    label: str
    col: int
    row: int
    enabled: bool = False
    fault: bool = False


@dataclass(frozen=True)
class Arrow:
    source: str
    target: str
    label: str


@dataclass(frozen=True)
class Family:
    key: str
    title: str
    control_ref: str
    status_ref: str
    control_bits: dict[int, str]
    status_bits: dict[int, str]
    states: tuple[StateBox, ...]
    arrows: tuple[Arrow, ...]
    commands: dict[Command, tuple[int, int]]
    """Command -> (bits to clear, bits to set) on the last control word."""
    edge_bits: dict[Command, int] = field(default_factory=dict)
    """Commands that act on a rising edge: bit cleared first, then set."""
    note: str = ""

    def state_of(self, status_word: int) -> str:
        raise NotImplementedError

    def state_box(self, key: str) -> StateBox | None:
        return next((box for box in self.states if box.key == key), None)


# --- CiA 402 ------------------------------------------------------------------------------------------------
CIA402_MASKS = (  # (mask, value, state) - CiA 402 / MICROMASTER table 3-18
    (0x4F, 0x00, "not_ready"), (0x4F, 0x40, "switch_on_disabled"), (0x6F, 0x21, "ready"),
    (0x6F, 0x23, "switched_on"), (0x6F, 0x27, "operation_enabled"), (0x6F, 0x07, "quick_stop_active"),
    (0x4F, 0x0F, "fault_reaction_active"), (0x4F, 0x08, "fault"),
)


class Cia402(Family):
    def state_of(self, status_word: int) -> str:
        return next((state for mask, value, state in CIA402_MASKS if status_word & mask == value), "unknown")


MM_CONTROL_BITS = {  # table 3-15: CANopen name / MICROMASTER control word 1 name
    0: "Switch on (ON/OFF1)", 1: "Enable voltage (OFF2)", 2: "Quick stop (OFF3)", 3: "Enable operation (pulse enable)",
    4: "RFG enable (op-mode specific)", 5: "RFG start (op-mode specific)", 6: "Setpoint enable (RFG zero)",
    7: "Fault reset (fault acknowledge)", 8: "Halt (not used in CAN)", 9: "Reserved", 10: "Reserved (control from PLC)",
    11: "Reverse", 12: "Not used", 13: "Motor pot. UP", 14: "Motor pot. DOWN", 15: "CDS bit 0 (local/remote)",
}
MM_STATUS_BITS = {  # table 3-17
    0: "Ready to switch on", 1: "Switched on", 2: "Operation enabled", 3: "Fault", 4: "Voltage enabled (MM: OFF2)",
    5: "Quick stop (0 = active)", 6: "Switch on disabled", 7: "Warning", 8: "Max frequency reached",
    9: "Remote (PZD control)", 10: "Target reached", 11: "Internal limit (MM: motor current limit, 0 = active)",
    12: "Op-mode specific (MM: motor holding brake active)", 13: "Op-mode specific (MM: motor overload, 0 = active)",
    14: "Motor runs direction right", 15: "Manufacturer specific (MM: inverter overload, 0 = active)",
}
"""Bits 11, 13, 15: table 3-17 prints no polarity, but every trace frame at rest has them set (0xFE..), as the MM
status word 1 r0052 shows these warnings low-active; the names say so."""
CIA402 = Cia402(
    key="cia402", title="CiA 402 drive state machine", control_ref="0x6040", status_ref="0x6041",
    control_bits=MM_CONTROL_BITS, status_bits=MM_STATUS_BITS,
    states=(StateBox("not_ready", "Not ready to switch on", 0, 0),
            StateBox("switch_on_disabled", "Switch on disabled", 0, 1),
            StateBox("ready", "Ready to switch on", 0, 2),
            StateBox("switched_on", "Switched on", 0, 3),
            StateBox("operation_enabled", "Operation enabled", 0, 4, enabled=True),
            StateBox("quick_stop_active", "Quick stop active", 1, 4, enabled=True),
            StateBox("fault_reaction_active", "Fault reaction active", 2, 0, fault=True),
            StateBox("fault", "Fault", 2, 1, fault=True)),
    arrows=(Arrow("not_ready", "switch_on_disabled", "1"), Arrow("switch_on_disabled", "ready", "2 Shutdown"),
            Arrow("ready", "switched_on", "3 Switch on"), Arrow("switched_on", "operation_enabled", "4 Enable"),
            Arrow("operation_enabled", "switched_on", "5 Disable op."), Arrow("switched_on", "ready", "6 Shutdown"),
            Arrow("ready", "switch_on_disabled", "7 QS / disable voltage"),
            Arrow("operation_enabled", "quick_stop_active", "11 Quick stop"),
            Arrow("quick_stop_active", "switch_on_disabled", "12"),
            Arrow("fault_reaction_active", "fault", "14"), Arrow("fault", "switch_on_disabled", "15 Fault reset")),
    commands={Command.SHUTDOWN: (0x8F, 0x06), Command.SWITCH_ON: (0x8F, 0x07),
              Command.ENABLE_OPERATION: (0x8F, 0x0F), Command.DISABLE_OPERATION: (0x8F, 0x07),
              Command.QUICK_STOP: (0x86, 0x02), Command.DISABLE_VOLTAGE: (0x82, 0x00),
              Command.FAULT_RESET: (0x00, 0x80)},
    edge_bits={Command.FAULT_RESET: 0x80},
    note="The control word acts only with P0700 = 6 (command source CAN); 0x6042 only with P1000 = 6. "
         "Bits 4...6 run the ramp-function generator in velocity mode (0x7F = run).",
)


# --- Lenze EMF2178IB -----------------------------------------------------------------------------------------
EMF_CONTROL_BITS = {
    0: "JOG selection bit 0 (NSET1-JOG1/3)", 1: "JOG selection bit 1 (NSET1-JOG2/3)",
    2: "Direction of rotation (DCTRL1-CW/CCW)", 3: "Quick stop (AIF-CTRL-QSP)", 4: "Stop RFG (NSET1-RFG1-STOP)",
    5: "RFG input = 0 (NSET1-RFG1-0)", 6: "Motor pot. UP (MPOT1-UP)", 7: "Motor pot. DOWN (MPOT1-DOWN)",
    8: "Freely configurable 9", 9: "Controller inhibit (AIF-CTRL-CINH)", 10: "External fault (AIF-CTRL-TRIP-SET)",
    11: "Reset fault (AIF-CTRL-TRIP-RESET)", 12: "Parameter set (DCTRL1-PAR2/4)",
    13: "Parameter set (DCTRL1-PAR3/4)", 14: "DC injection brake (MCTRL1-DCB)", 15: "Freely configurable 16",
}
EMF_STATUS_BITS = {
    0: "Current parameter set (DCTRL-PAR-B0)", 1: "Pulse inhibit (DCTRL1-IMP)", 2: "Imax limit (MCTRL1-IMAX)",
    3: "Output frequency = setpoint (MCTRL1-RFG1=NOUT)", 4: "RFG input = output (NSET1-RFG1-I=0)",
    5: "Qmin threshold (PCTRL1-QMIN)", 6: "Output frequency = 0 (DCTRL1-NOUT=0)",
    7: "Controller inhibit (DCTRL1-CINH)", 8: "Device status (DCTRL1-STAT*1)", 9: "Device status (DCTRL1-STAT*2)",
    10: "Device status (DCTRL1-STAT*4)", 11: "Device status (DCTRL1-STAT*8)",
    12: "Overtemperature warning (DCTRL1-OH-WARN)", 13: "DC-bus overvoltage (DCTRL1-OV)",
    14: "Direction of rotation (DCTRL1-CCW)", 15: "Ready for operation (DCTRL1-RDY)",
}
LENZE_STATE_KEYS = {0: "init", 1: "init", 2: "switch_on_inhibit", 3: "operation_inhibited", 4: "flying_restart",
                    5: "dc_brake", 6: "operation_enabled", 7: "message", 8: "fault", 10: "fail_qsp",
                    15: "no_communication"}


class Emf2178(Family):
    def state_of(self, status_word: int) -> str:
        return LENZE_STATE_KEYS.get(status_word >> 8 & 0x0F, "unknown")


EMF = Emf2178(
    key="emf2178ib", title="Lenze device control (EMF2178IB: AIF-CTRL / AIF-STAT)", control_ref="C0135",
    status_ref="C0150", control_bits=EMF_CONTROL_BITS, status_bits=EMF_STATUS_BITS,
    states=(StateBox("init", "Device initialisation", 0, 0), StateBox("switch_on_inhibit", "Switch-on inhibit", 0, 1),
            StateBox("operation_inhibited", "Operation inhibited", 0, 2),
            StateBox("operation_enabled", "Operation enabled", 0, 3, enabled=True),
            StateBox("flying_restart", "Flying restart circuit active", 2, 3, enabled=True),
            StateBox("dc_brake", "DC injection brake active", 1, 3, enabled=True),
            StateBox("message", "Message active", 2, 0, fault=True),
            StateBox("fault", "Fault active", 2, 1, fault=True),
            StateBox("fail_qsp", "Fail-QSP", 1, 0, fault=True)),
    arrows=(Arrow("init", "switch_on_inhibit", "C0142 = 0"), Arrow("init", "operation_inhibited", "C0142 = 1"),
            Arrow("switch_on_inhibit", "operation_inhibited", "CINH once"),
            Arrow("operation_inhibited", "operation_enabled", "CINH = 0"),
            Arrow("operation_enabled", "operation_inhibited", "CINH = 1"),
            Arrow("fault", "operation_inhibited", "TRIP-RESET")),
    commands={Command.SHUTDOWN: (0x0000, 0x0200), Command.DISABLE_OPERATION: (0x0000, 0x0200),
              Command.ENABLE_OPERATION: (0x0E08, 0x0000), Command.QUICK_STOP: (0x0000, 0x0008),
              Command.DISABLE_VOLTAGE: (0x0000, 0x0200), Command.FAULT_RESET: (0x0400, 0x0800)},
    edge_bits={Command.FAULT_RESET: 0x0800},
    note="Process data (and C0135) act only with C0001 = 3 (8200 vector) or C0005 = xxx3 (93XX); terminal 28 "
         "(controller enable) must be HIGH. Shutdown / disable = CINH, enable = CINH and QSP cleared.",
)


# --- Lenze 8400 ----------------------------------------------------------------------------------------------
L8400_KEYS = {1: "init", 3: "ready", 4: "switched_on", 5: "operation_enabled", 7: "trouble", 8: "fault"}
L8400_CONTROL_BITS = {
    0: "SwitchOn", 1: "DisableVoltage", 2: "SetQuickStop", 3: "EnableOperation", 4: "ModeSpecific_1",
    5: "ModeSpecific_2", 6: "ModeSpecific_3", 7: "ResetFault", 8: "SetCInh (controller inhibit)", 9: "Reserved_1",
    10: "SetSpeedCcw", 11: "LenzeSpecific_1", 12: "JogSpeed1", 13: "JogSpeed2", 14: "SetFail", 15: "LenzeSpecific_4",
}
L8400_STATUS_BITS = {
    0: "FreeStatusBit0", 1: "PulseInhibit", 2: "FreeStatusBit2", 3: "FreeStatusBit3", 4: "QuickStopIsActive",
    5: "FreeStatusBit5", 6: "SpeedActEqual0", 7: "ControllerInhibit", 8: "StatusCodeBit0", 9: "StatusCodeBit1",
    10: "StatusCodeBit2", 11: "StatusCodeBit3", 12: "Warning", 13: "Trouble / fault", 14: "RotationCcw",
    15: "ReadyForOperation",
}


class Lenze8400(Family):
    def state_of(self, status_word: int) -> str:
        return L8400_KEYS.get(status_word >> 8 & 0x0F, "unknown")


L8400 = Lenze8400(
    key="lenze8400", title="Lenze 8400 device control (CAN1_IN wCtrl / CAN1_OUT status word)",
    control_ref="C00866/1", status_ref="C00868/1", control_bits=L8400_CONTROL_BITS, status_bits=L8400_STATUS_BITS,
    states=(StateBox("init", "Init", 0, 0), StateBox("ready", "Ready to switch on", 0, 1),
            StateBox("switched_on", "Switched on", 0, 2),
            StateBox("operation_enabled", "Operation enabled", 0, 3, enabled=True),
            StateBox("trouble", "Trouble", 2, 2, fault=True), StateBox("fault", "Fault", 2, 1, fault=True)),
    arrows=(Arrow("init", "ready", ""), Arrow("ready", "switched_on", "SwitchOn"),
            Arrow("switched_on", "operation_enabled", "EnableOperation"),
            Arrow("operation_enabled", "ready", "SetCInh"), Arrow("fault", "ready", "ResetFault")),
    commands={Command.SHUTDOWN: (0x0109, 0x0000), Command.SWITCH_ON: (0x0108, 0x0001),
              Command.ENABLE_OPERATION: (0x0104, 0x0009), Command.DISABLE_OPERATION: (0x0008, 0x0001),
              Command.QUICK_STOP: (0x0000, 0x0004), Command.DISABLE_VOLTAGE: (0x0009, 0x0100),
              Command.FAULT_RESET: (0x4000, 0x0080)},
    edge_bits={Command.FAULT_RESET: 0x0080},
    note="The 8400 CANopen manual names CAN1_IN word 1 only 'wCtrl'; bit names here follow the 8400 network "
         "control word (LA_NCtrl) as the simulator implements it - check them against the 8400 reference manual.",
)

EMF_93XX_CONTROL_BITS = {  # EMF2178IB ch. 9.3.1.2, column 9300 servo inverter C0005 = 1xx3 (speed control)
    0: "NSET-JOG*1", 1: "NSET-JOG*2", 2: "NSET-N-INV", 3: "Quick stop (AIF-CTRL.QSP)", 4: "NSET-RFG-STOP",
    5: "NSET-RFG-0", 6: "Not assigned", 7: "Not assigned", 8: "Not assigned", 9: "Controller inhibit (AIF-CTRL.CINH)",
    10: "External fault (AIF-CTRL.TRIP-SET)", 11: "Reset fault (AIF-CTRL.TRIP-RESET)", 12: "DCTRL-PAR*1",
    13: "DCTRL-PAR-LOAD", 14: "NSET-Ti*1", 15: "NSET-Ti*2",
}
EMF_93XX_STATUS_BITS = {  # same column of the 93XX status word table
    0: "DCTRL-PAR1-0", 1: "Pulse inhibit (DCTRL-IMP)", 2: "MCTRL-IMAX", 3: "MCTRL-MMAX", 4: "NSET-RFG-I=0",
    5: "QMIN", 6: "DCTRL-NACT=0", 7: "Controller inhibit (DCTRL-CINH)", 8: "Device status bit 0",
    9: "Device status bit 1", 10: "Device status bit 2", 11: "Device status bit 3", 12: "DCTRL-WARN",
    13: "DCTRL-MESS", 14: "DCTRL-CW/CCW", 15: "Ready for operation (DCTRL-RDY)",
}
EMF_AIF = replace(EMF, key="emf2178ib-aif", control_ref="C1822/1", status_ref="C1823/1",
                  title="Lenze device control (EMF2178IB: AIF-IN / AIF-OUT word 1)",
                  control_bits=EMF_93XX_CONTROL_BITS, status_bits=EMF_93XX_STATUS_BITS,
                  note=EMF.note + " 93XX bit names: the manual's column for C0005 = 1xx3 (speed control); other "
                       "signal configurations assign bits 0...2, 4, 5, 12...15 differently.")
"""93XX: no C0135/C0150 on the bus; the control and status words are AIF word 1 (RPDO1 / TPDO1), bits named as
the EMF2178IB manual's 93XX tables name them (not the 8200 vector's)."""

FAMILIES = (CIA402, EMF, EMF_AIF, L8400)


def _has(catalog: Catalog, ref: str) -> bool:
    try:
        catalog.resolve(ref)
    except UnknownParameter:
        return False
    return True


def family_of(catalog: Catalog | None) -> Family | None:
    """The device control a profile offers (None: the device has no control word the panel knows)."""
    if catalog is None:
        return None
    return next((family for family in FAMILIES
                 if _has(catalog, family.control_ref) and _has(catalog, family.status_ref)), None)


def state_label(family: Family, key: str) -> str:
    box = family.state_box(key)
    return box.label if box else "Unknown state"


def next_control_word(family: Family, command: Command, last: int) -> int:
    clear, set_bits = family.commands[command]
    return (last & ~clear & 0xFFFF) | set_bits
