"""The ``control`` and ``commissioning`` sections of a device profile: how a drive is switched, set and watched.

``control`` holds what the Control tab and the simulated drive need to know of a device beyond its object
dictionary: the state machine (``cia402``: the CiA 402 status-word masks; ``lenze``: a device-status field of the
status word; ``none``), where the control and status words live and what each bit is called, the commands as bits
to clear and set, setpoints and actual values with their scaling, the jog plan and the modes of operation.
``simulation`` names the simulator's drive model (a named behaviour: what cannot be data).

``commissioning`` holds the manuals' guided sequences as telegram data: SDO downloads (index, subindex, the data
bytes and the request as the manual prints it), NMT start, process-data telegrams (COB-ID base + data) and checks.

A device whose EDS has 0x6040/0x6041 and no ``control`` section gets the standard CiA 402 section
(:mod:`drivebench.device.drive.cia402`).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, WithJsonSchema, model_validator

from drivebench.device.profiles.templates import check_template
from drivebench.i18n import N_


def _parse_int(value: object) -> object:
    return int(value.strip(), 0) if isinstance(value, str) else value


WORD_SCHEMA = {"anyOf": [{"type": "integer"}, {"type": "string", "pattern": r"^0[xX][0-9a-fA-F]+$"}]}
Word = Annotated[int, BeforeValidator(_parse_int), PlainSerializer(lambda v: f"0x{v:04X}", return_type=str),
                 WithJsonSchema(WORD_SCHEMA)]
"""A control-word bit pattern, written ``"0x008F"`` in the files."""
HexBytes = Annotated[bytes, BeforeValidator(lambda v: bytes.fromhex(v) if isinstance(v, str) else v),
                     PlainSerializer(lambda v: v.hex(" "), return_type=str),
                     WithJsonSchema({"type": "string", "pattern": r"^([0-9a-fA-F]{2}( |$))*$"})]
"""Telegram data as the manuals print it: ``"7f 00 e8 03"``."""


# DriveBench's own defaults of a section (not a manual's words): shown in the reader's language (cia402.shown)
SETPOINT_JOG = N_("Setpoint jog at {percent:g} percent of the range ({value:g} {unit}): {why}.")
NO_JOG = N_("this device's profile gives the panel no jog function")
NOT_NAMED = N_("this device's profile does not name it")
ACTUAL_KINDS = [N_("Speed"), N_("Current"), N_("DC-bus voltage"), N_("Torque"), N_("Heat-sink temperature")]
DRIVEBENCH_TEXTS = (SETPOINT_JOG, NO_JOG, NOT_NAMED, *ACTUAL_KINDS)


class Command(StrEnum):
    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch_on"
    ENABLE_OPERATION = "enable_operation"
    DISABLE_OPERATION = "disable_operation"
    QUICK_STOP = "quick_stop"
    DISABLE_VOLTAGE = "disable_voltage"
    FAULT_RESET = "fault_reset"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class StateBox(_Model):
    """A state of the drawn state machine: its key, name, grid place (column, row), and whether the motor may turn
    in it (``enabled``) or it is a fault."""

    key: str
    label: str
    col: int
    row: int
    enabled: bool = False
    fault: bool = False


class Arrow(_Model):
    """A drawn transition between two states (their keys)."""

    from_state: str
    to_state: str
    label: str = ""


class CommandBits(_Model):
    """A command as a change of the last control word: ``(last & ~clear) | set``; ``edge`` bits act on a rising
    edge (written 0 first when they are 1)."""

    clear: Word = 0
    set: Word = 0
    edge: Word | None = None


class WordScale(_Model):
    """A process-data word: user value = signed 16-bit raw / ``raw_per_unit``; or ``full_scale_raw`` stands for
    the value of ``reference_ref`` (8400: 0x4000 = C00011, the motor reference speed)."""

    raw_per_unit: float | None = None
    full_scale_raw: int | None = None
    reference_ref: str | None = None
    reference_default: float = 1.0


class Setpoint(_Model):
    ref: str
    unit: str
    modes: list[int] = Field(default_factory=list)
    """Modes of operation this setpoint serves ([]: whatever the mode)."""
    scale: WordScale | None = None
    """None: the profile entry's own scaling."""
    min: float | None = None
    max: float | None = None
    limit_ref: str | None = None
    """The range is ± the value of this object (0x6046.2 max velocity), ``max`` when it cannot be read."""
    limit_times_reference: float | None = None
    """The range is ± this many times the scale's reference value (8400: 2 x C00011)."""
    run_bits: Word | None = None
    """After the setpoint, set these control-word bits once ``run_when`` bits are all set (velocity mode RFG)."""
    run_when: Word = 0


class ActualSpec(_Model):
    label: str
    """The kind first (``Speed``, ``Current``, ``DC-bus voltage``, ``Torque``, ``Heat-sink temperature``, …)."""
    ref: str
    scale: WordScale | None = None
    unit: str | None = None
    """Unit of a scaled word (the entry's own unit otherwise)."""
    decimals: int = 2


class JogPlan(_Model):
    """How the panel jogs: ``device`` (control-word bits select the device's own jog value), ``setpoint`` (the panel
    sends a setpoint: ``percent_ref`` of ``reference_ref``, else ``fraction`` of the setpoint range), or
    ``profile_velocity`` (CiA 402 mode 3 at a speed the user sets, see the generic section). ``text`` may name
    ``{value}``, ``{unit}``, ``{percent}``, ``{reference}`` and ``{word}``."""

    method: Literal["device", "setpoint", "profile_velocity"] = "setpoint"
    text: str = SETPOINT_JOG
    why: str = NO_JOG
    fraction: float = 0.1
    percent_ref: str | None = None
    reference_ref: str | None = None
    reference_default: float = 1.0
    value_ref: str | None = None
    unit: str | None = None
    select_mask: Word = 0
    forward: Word = 0
    reverse: Word = 0
    enabled_ref: str | None = None
    enabled_max: float | None = None
    """The device jog acts only while ``enabled_ref`` <= ``enabled_max``; ``disabled_why`` says why not."""
    disabled_why: str | None = None

    @model_validator(mode="after")
    def _check_text(self) -> JogPlan:
        """``text`` may name the fields of its method (``services/control/drive_control.jog_plan`` fills them)."""
        if self.text == SETPOINT_JOG:
            return self
        samples: dict[str, object] = {"value": 1.0, "unit": "rpm"}
        if self.method == "device":
            samples["word"] = "C00135"
        elif self.method == "setpoint":
            samples |= {"percent": 1.0, "reference": 1.0} if self.percent_ref else {"percent": 1.0, "why": "-"}
        check_template(self.text, samples, "jog.text")
        return self


class ControlSection(_Model):
    key: str = Field(pattern=r"^[a-z0-9][a-z0-9_.-]*$")
    """The device control's name in the API (``cia402``, ``lenze8400`` …)."""
    state_machine: Literal["cia402", "lenze", "none"]
    title: str
    note: str = ""
    control_word: str
    status_word: str
    control_bits: dict[int, str] = Field(default_factory=dict)
    status_bits: dict[int, str] = Field(default_factory=dict)
    states: list[StateBox] = Field(default_factory=list)
    arrows: list[Arrow] = Field(default_factory=list)
    state_codes: dict[int, str] = Field(default_factory=dict)
    """``lenze``: device status (status word bits 8...11) -> state key."""
    commands: dict[Command, CommandBits] = Field(default_factory=dict)
    moving_commands: list[Command] = Field(default_factory=lambda: [Command.ENABLE_OPERATION, Command.FAULT_RESET])
    """Commands after which the motor may turn (fault reset too: a drive may restart by itself)."""
    setpoints: list[Setpoint] = Field(default_factory=list)
    actual_values: list[ActualSpec] = Field(default_factory=list)
    actual_kinds: list[str] = Field(default_factory=lambda: list(ACTUAL_KINDS))
    """The kinds the panel looks for; the ones the device lacks are named with ``missing_why``."""
    missing_why: str = NOT_NAMED
    jog: JogPlan = Field(default_factory=JogPlan)
    modes: dict[int, str] = Field(default_factory=dict)
    """Modes of operation (0x6060) the panel offers."""
    mode_refused: str | None = None
    """Said when 0x6061 does not follow a 0x6060 write (``{mode}``, ``{shown}``)."""
    modes_help: str | None = None
    """Said when a mode outside ``modes`` is asked for."""
    simulation: str | None = None
    """The simulator's drive model for this device (a named behaviour: ``cia402_vf_inverter``, ``lenze_8400``,
    ``lenze_emf2178ib``, ``cia402_servo``)."""

    @model_validator(mode="after")
    def _states_known(self) -> ControlSection:
        keys = {box.key for box in self.states}
        named = [(f"arrow {n + 1}", key) for n, arrow in enumerate(self.arrows)
                 for key in (arrow.from_state, arrow.to_state)]
        unknown = [f"{where}: '{key}'" for where, key in named if key not in keys]
        if unknown:
            raise ValueError(f"states not among the section's states ({', '.join(sorted(keys))}): "
                             + "; ".join(unknown))
        return self

    @model_validator(mode="after")
    def _check_texts(self) -> ControlSection:
        if self.mode_refused is not None:
            check_template(self.mode_refused, {"shown": 0, "mode": 2}, "mode_refused")
        if self.modes_help is not None:
            check_template(self.modes_help, {"mode": 2}, "modes_help")
        return self


# --- commissioning ---------------------------------------------------------------------------------------------
class Step(_Model):
    title: str
    kind: Literal["sdo", "nmt_start", "pdo", "check", "parameter"]
    """``sdo``: download ``data`` to index/sub; ``nmt_start``; ``pdo``: send ``data`` on ``cob`` + node id;
    ``check``: read ``expect_ref``; ``parameter``: write ``ref`` with the value the user gives (else ``proposal``)
    through the checked write, read back."""
    ref: str | None = None
    """The parameter a ``parameter`` step sets (a vendor code or an index)."""
    proposal: int | float | str | None = None
    """The value the form offers for a ``parameter`` step; without one the user must give a value."""
    index: Word = 0
    sub: int = 0
    data: HexBytes = b""
    cob: Word = 0
    expect_state: str | None = None
    expect_ref: str | None = None
    expect_value: int | None = None
    printed: str | None = None
    """The request as the manual prints it."""
    moves: bool = False
    note: str | None = None

    @model_validator(mode="after")
    def _parameter_named(self) -> Step:
        if self.kind == "parameter" and not self.ref:
            raise ValueError(f"step '{self.title}': a parameter step names its parameter (ref)")
        return self


class Sequence(_Model):
    key: str
    title: str
    source: str
    preconditions: list[str] = Field(default_factory=list)
    requires: list[str] = Field(default_factory=list)
    """Offered only when the device has these objects / codes."""
    missing: list[str] = Field(default_factory=list)
    """Steps of the manual's sequence this profile cannot offer (a parameter it lacks), each with why."""
    steps: list[Step]
