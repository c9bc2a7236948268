"""The ``switches`` section of a device profile: how node address and baud rate are set, and the COB-IDs that follow.

* ``switches``: the DIP switches as drawn on the housing (label, ``address`` with its weight or ``baud``), and the
  manual's ``baud_table`` (switch positions -> bit rate); a device without switches lists none;
* ``node_parameter`` / ``baud_parameter``: the parameters the device takes node id and baud rate from when the
  switches leave it to them (``all_address_off``, ``all_baud_off``), with their factory values;
* ``settings``: the parameter values that set the same without switches (the calculator's "alternative");
* ``rules`` (with the decode cases each one explains), ``ambiguities``: the manual's words, shown as they are;
* ``cob_ids``: the base identifiers of its services, which channels are on in the factory setting, another set of
  base identifiers the device can select (``alternative``), services that reuse another's identifiers of a node
  id further on (``shares_with``: SDO2 = SDO1 of address + 64).

``device/calculators/dip.py`` evaluates the section (the DIP-switch calculator, the network planner); profiles
that share a module hold the same ``key`` and the same section.
"""

from __future__ import annotations

from string import Formatter
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivebench.device.profiles.hex_int import HexInt
from drivebench.device.profiles.templates import check_template
from drivebench.i18n import N_, Text

Key = Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_.-]*$", max_length=64)]
Direction = Literal["to node", "from node", "broadcast"]
DIRECTION_TEXTS = (N_("to node"), N_("from node"), N_("broadcast"))
"""The directions as the COB-ID table shows them (translated there: the profile's value stays the English key)."""
Case = Literal["node_from_switches", "node_above_range", "node_from_parameter", "baud_from_switches",
               "baud_from_parameter"]
"""What a decode found: where the node id and the baud rate came from."""
INFRASTRUCTURE = ("nmt", "sync", "emcy", "heartbeat")
"""Channels that are always on (not switched by a planner)."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _check_template(text: str, samples: dict[str, object], where: str) -> None:
    """``samples``: the fields the text is formatted with, each with a value of the type it gets."""
    try:
        names = {name for _, name, _, _ in Formatter().parse(text) if name is not None}
    except ValueError:  # a text that does not parse: refused in check_template's words
        names = set()
    unknown = names - set(samples)
    if unknown:
        raise ValueError(Text(N_("{where} may use {allowed} only, not {unknown}"), where=where,
                              allowed=", ".join("{" + n + "}" for n in sorted(samples)),
                              unknown=", ".join("{" + n + "}" for n in sorted(unknown))))
    check_template(text, samples, where)


class Switch(_Model):
    label: str = Field(min_length=1, max_length=8)
    """As printed on the housing / in the manual: ``64``, ``a``, ``S1``."""
    role: Literal["address", "baud"]
    weight: int | None = Field(None, ge=1, le=64)
    """Address value of the switch when ON (the sum of the ON address switches is the address); a power of two."""
    readback_bit: int | None = Field(None, ge=0, le=31)
    """Its bit in the read-back parameter (``readback``)."""


class BaudRow(_Model):
    baud_kbit: int = Field(gt=0)
    positions: dict[str, bool]
    """Baud switch label -> ON, one row of the manual's table."""


class NodeParameter(_Model):
    """The parameter the node id comes from when the address switches leave it to a parameter."""

    code: str = Field(min_length=1)
    range: tuple[int, int]
    """Node ids it accepts."""
    default: int | None = Field(None, ge=0, le=255)
    """Factory value (None: not known)."""
    default_note: str | None = None
    """Said when its value is not given and the factory value is used."""
    invalid: str
    """Problem for a value outside ``range``: ``{code}``, ``{value}``, ``{lo}``, ``{hi}``."""

    @model_validator(mode="after")
    def _check(self) -> NodeParameter:
        if not 0 <= self.range[0] <= self.range[1] <= 127:
            raise ValueError(Text(N_("range {range} is not within 0 … 127 (lowest first)"), range=list(self.range)))
        _check_template(self.invalid, {"code": self.code, "value": 1, "lo": 1, "hi": 1}, "invalid")
        return self


class BaudParameter(_Model):
    """The parameter the baud rate comes from when the switches leave it to a parameter."""

    code: str = Field(min_length=1)
    rates_kbit: list[int] = Field(min_length=1)
    """Baud rates it can select."""
    default_kbit: int | None = None
    invalid: str
    """Problem for a baud rate it cannot select: ``{code}``, ``{value}``."""

    @model_validator(mode="after")
    def _check(self) -> BaudParameter:
        _check_template(self.invalid, {"code": self.code, "value": 125}, "invalid")
        return self


class Setting(_Model):
    """A parameter value that sets node id or baud rate without switches."""

    code: str = Field(min_length=1)
    sets: Literal["node_id", "baud"]
    values: dict[int, int | None] = Field(default_factory=dict)
    """Baud settings: baud rate [kbit/s] -> value to write (None: value not in the manual text); a baud rate not
    listed cannot be set by it. Empty: the value is the baud rate in kbit/s (or the node id)."""
    meaning: str
    """``{node_id}``, ``{baud_kbit}``, ``{value}``."""
    note: str | None = None
    unavailable: str | None = None
    """Note when this parameter cannot set the value (only the switches can)."""

    @model_validator(mode="after")
    def _check(self) -> Setting:
        if self.sets == "node_id" and self.values:
            raise ValueError(Text(N_("values are baud rate -> value; a node id setting writes the node id itself")))
        for text in (self.meaning, self.note or "", self.unavailable or ""):
            _check_template(text, {"node_id": 1, "baud_kbit": 125, "value": None}, "meaning/note")
        return self


class Readback(_Model):
    """The parameter that shows the switch positions read at switch-on (each switch's ``readback_bit``)."""

    code: str = Field(min_length=1)
    set_bits: list[int] = Field(default_factory=list)
    """Bits that are set in every read-back."""


class Rule(_Model):
    text: str = Field(min_length=1)
    when: list[Case] = Field(default_factory=list)
    """The decode cases this rule explains (listed under "the manual's rule that applies")."""


class Service(_Model):
    """One row of the device's identifier table: COB-ID = base + node id (NMT and SYNC have no node part)."""

    name: str = Field(min_length=1)
    """``TPDO1``, ``SDO1 rx`` ... (rx/tx from the node's point of view: rx = client -> server)."""
    channel: str = Field(pattern=r"^[a-z0-9_]+$")
    """What a planner switches on or off: ``sdo2``, ``pdo1`` ... (or ``nmt``, ``sync``, ``emcy``, ``heartbeat``)."""
    base: HexInt = Field(ge=0, le=0x7FF)
    direction: Direction
    node_specific: bool = True
    default_on: bool = True
    alternative_base: HexInt | None = Field(None, ge=0, le=0x7FF)
    """Base identifier when the ``alternative`` identifiers are selected, where it differs."""
    shares_with: str | None = None
    """The service whose identifiers this one reuses for a node id further on (``SDO1 rx`` for ``SDO2 rx``)."""
    source: str = ""


class AlternativeIds(_Model):
    """Another set of base identifiers the device can select (beside CiA 301's predefined connection set)."""

    key: Key
    """What a request or a plan names (``pdo_ids``)."""
    name: str
    """Shown beside the choice: ``Lenze base IDs``."""
    label: str
    """Before a base in a note: ``Lenze base ID``."""
    short: str
    """In the planner's row: ``Lenze (0x281)``."""
    selected_by: str
    """The setting that selects them: ``C00353 = 0``."""
    standard_by: str
    """The setting that selects the standard ones: ``C00353 = 1, Lenze setting``."""
    remedy: str
    """What to set against a collision they cause: ``C00353 = 1``."""


class CobIdRules(_Model):
    services: list[Service] = Field(min_length=1)
    notes: list[str] = Field(default_factory=list)
    alternative: AlternativeIds | None = None

    @model_validator(mode="after")
    def _check(self) -> CobIdRules:
        names = [s.name for s in self.services]
        for name in {n for n in names if names.count(n) > 1}:
            raise ValueError(Text(N_("service '{name}' is listed twice"), name=name))
        for svc in self.services:
            if svc.shares_with is not None:
                other = next((s for s in self.services if s.name == svc.shares_with), None)
                if other is None:
                    raise ValueError(Text(N_("{name}: shares_with names '{shares_with}', which is not a service"),
                                          name=svc.name, shares_with=svc.shares_with))
                if not 0 < svc.base - other.base < 128:
                    raise ValueError(Text(N_("{name}: its base must lie 1 … 127 above the base of {other}"),
                                          name=svc.name, other=other.name))
            if svc.alternative_base is not None and self.alternative is None:
                raise ValueError(Text(N_("{name}: alternative_base needs an 'alternative' set of identifiers"),
                                      name=svc.name))
        if self.alternative is not None and self.alternative.key == "canopen":
            raise ValueError(Text(N_("alternative.key 'canopen' names the standard identifiers; choose another key")))
        return self

    def service(self, name: str) -> Service:
        return next(s for s in self.services if s.name == name)


class SwitchesSection(_Model):
    key: Key
    """The device key of the calculator and the network planner; profiles of one module share it."""
    aliases: list[str] = Field(default_factory=list)
    """Other names that select this device (older keys, short forms); case does not matter."""
    name: str = Field(min_length=1)
    short_name: str = Field(min_length=1)
    manual: str = ""
    housing_colour: str | None = Field(None, pattern=r"^#[0-9a-fA-F]{6}$")
    switches: list[Switch] = Field(default_factory=list)
    """Drawing order, left to right."""
    baud_table: list[BaudRow] = Field(default_factory=list)
    baud_table_source: str = "the manual's"
    """Where the table is printed (``§6.3.1``)."""
    switch_node_range: tuple[int, int] | None = None
    """Node ids the address switches can give."""
    above_range_node_id: int | None = Field(None, ge=1, le=127)
    """The node id the device uses when the switches add up to more than ``switch_node_range`` allows."""
    all_address_off: Literal["node_from_parameter", "node_and_baud_from_parameters"] = "node_from_parameter"
    """All address switches OFF: the node id (and the baud rate, the baud switches then ignored) from the
    parameters."""
    all_baud_off: Literal["table", "baud_from_parameter"] = "table"
    """All baud switches OFF: the baud table's row, or the baud rate from the parameter."""
    baud_rates_kbit: list[int] = Field(min_length=1)
    node_parameter: NodeParameter
    baud_parameter: BaudParameter
    settings: list[Setting] = Field(default_factory=list)
    readback: Readback | None = None
    factory_setting: str = ""
    """The factory setting in words (``All switches OFF …``)."""
    rules: list[Rule] = Field(default_factory=list)
    ambiguities: list[str] = Field(default_factory=list)
    cob_ids: CobIdRules

    @property
    def address_switches(self) -> list[Switch]:
        return [s for s in self.switches if s.role == "address"]

    @property
    def baud_switches(self) -> list[Switch]:
        return [s for s in self.switches if s.role == "baud"]

    @property
    def node_range(self) -> tuple[int, int]:
        """Node ids the device can use at all (by switches or by its parameter)."""
        lo, hi = self.node_parameter.range
        if self.switch_node_range is None:
            return lo, hi
        return min(lo, self.switch_node_range[0]), max(hi, self.switch_node_range[1])

    def configured_values(self, node_id: int, bitrate: int) -> dict[str, int]:
        """What the setting parameters hold on a device configured for ``node_id`` at ``bitrate`` (bit/s): each
        setting's code -> its value (a baud setting without a value for that rate is left out). A device with
        switches takes both from its switches: its setting parameters keep what they hold (none here)."""
        if self.switches:
            return {}
        kbit = bitrate // 1000
        values: dict[str, int] = {}
        for setting in self.settings:
            if setting.sets == "node_id":
                values[setting.code] = node_id
            elif not setting.values:
                values[setting.code] = kbit
            elif (value := setting.values.get(kbit)) is not None:
                values[setting.code] = value
        return values

    @model_validator(mode="after")
    def _check(self) -> SwitchesSection:
        labels = [s.label.lower() for s in self.switches]
        for label in {lab for lab in labels if labels.count(lab) > 1}:
            raise ValueError(Text(N_("switch '{label}' is listed twice"), label=label))
        self._check_address()
        self._check_baud()
        if self.readback is not None and any(s.readback_bit is None for s in self.switches):
            raise ValueError(Text(N_("with a readback every switch needs its readback_bit")))
        return self

    def _check_address(self) -> None:
        weights = [s.weight for s in self.address_switches]
        if any(w is None for w in weights):
            raise ValueError(Text(N_("every address switch needs its weight")))
        if any(s.weight is not None for s in self.baud_switches):
            raise ValueError(Text(N_("baud switches have no weight")))
        if any(w is not None and w & (w - 1) for w in weights) or len(set(weights)) != len(weights):
            raise ValueError(Text(N_("address switch weights must be distinct powers of two (1, 2, 4 … 64)")))
        if self.address_switches and self.switch_node_range is None:
            raise ValueError(Text(N_("address switches need a switch_node_range")))
        if self.switch_node_range is not None:
            lo, hi = self.switch_node_range
            top = sum(w or 0 for w in weights)
            if not 1 <= lo <= hi <= min(top, 127):
                raise ValueError(Text(N_("switch_node_range {value} is not within 1 … {top} (the sum of the address "
                                         "switch weights)"), value=[lo, hi], top=min(top, 127)))

    def _check_baud(self) -> None:
        baud_labels = [s.label for s in self.baud_switches]
        seen: set[tuple[bool, ...]] = set()
        for number, row in enumerate(self.baud_table):
            if set(row.positions) != set(baud_labels):
                raise ValueError(Text(N_("baud_table row {number} ({baud_kbit} kbit/s) names switches {named}; it "
                                         "must name each baud switch ({labels}) once"), number=number,
                                      baud_kbit=row.baud_kbit, named=", ".join(row.positions) or Text(N_("none")),
                                      labels=", ".join(baud_labels) or Text(N_("there are none"))))
            pattern = tuple(row.positions[label] for label in baud_labels)
            if pattern in seen:
                raise ValueError(Text(N_("baud_table row {number}: the same switch positions as an earlier row"),
                                      number=number))
            seen.add(pattern)
            if row.baud_kbit not in self.baud_rates_kbit:
                raise ValueError(Text(N_("baud_table row {number}: {baud_kbit} kbit/s is not in baud_rates_kbit"),
                                      number=number, baud_kbit=row.baud_kbit))
        if baud_labels:
            missing = set(self.baud_rates_kbit) - {row.baud_kbit for row in self.baud_table}
            if missing:
                raise ValueError(Text(N_("baud rates {values} have no row in baud_table"), values=sorted(missing)))
