"""DIP-switch calculator: node address and baud rate from a device's switch block, and back.

Each family's switch block is data (labels, address weights, the manual's baud-rate table, the special
positions and the codes that take over when the switches say so). ``decode`` reads switch positions the way
the device reads them at switch-on; ``encode`` gives the switch positions for a node id and baud rate,
together with the parameter values that set the same thing without switches. MICROMASTER has no switches: node
id and baud rate are parameters.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from drivebench.errors import InvalidValue, OutOfRange, UnknownProfile
from drivebench.i18n import N_

LENZE_8400_MOTEC = "lenze-8400-motec"
LENZE_EMF2178IB = "lenze-emf2178ib"
SIEMENS_MM4 = "siemens-mm4"

_M8400 = "8400 motec CANopen manual (EDS84DMOTCAN EN 3.0)"
_MEMF = "EMF2178IB manual (EDSMF2178IB EN 3.0)"
_MMM4 = "MICROMASTER 420/430/440 CANopen option module manual (6SE6400-5BC00-0BP0, 01/05)"


class Switch(BaseModel):
    label: str
    """As printed on the housing / in the manual: ``64`` or ``a`` (8400 motec), ``S1`` (EMF2178IB)."""
    role: Literal["address", "baud"]
    weight: int | None = None
    """Address value of the switch when ON (the sum of the ON switches is the address)."""


class BaudRow(BaseModel):
    baud_kbit: int
    positions: dict[str, bool]
    """Baud switch label -> ON, one row of the manual's table."""


class ParameterSetting(BaseModel):
    """A parameter value that sets node id or baud rate without switches."""

    code: str
    value: int | None
    meaning: str
    note: str | None = None


class FamilySpec(BaseModel):
    key: str
    name: str
    manual: str
    switches: list[Switch] = Field(default_factory=list)
    """Drawing order, left to right."""
    baud_table: list[BaudRow] = Field(default_factory=list)
    switch_node_range: tuple[int, int] | None = None
    """Node ids the address switches can give."""
    code_node_range: tuple[int, int]
    """Node ids the address parameter accepts."""
    baud_rates_kbit: list[int]
    node_code: str
    baud_code: str
    baud_code_values: dict[int, int | None] = Field(default_factory=dict)
    """Baud rate [kbit/s] -> value of the baud-rate parameter (None: value not in the manual text we have)."""
    lenze_setting: str
    rules: list[str] = Field(default_factory=list)
    """The manual's rules for switches vs parameters, quoted with their section."""
    ambiguities: list[str] = Field(default_factory=list)

    @property
    def address_switches(self) -> list[Switch]:
        return [s for s in self.switches if s.role == "address"]

    @property
    def baud_switches(self) -> list[Switch]:
        return [s for s in self.switches if s.role == "baud"]


def _rows(labels: tuple[str, ...], table: dict[int, str]) -> list[BaudRow]:
    """Build baud rows from compact strings like ``"101"`` (1 = ON) in the order of ``labels``."""
    return [
        BaudRow(baud_kbit=kbit, positions={lab: bit == "1" for lab, bit in zip(labels, bits, strict=True)})
        for kbit, bits in table.items()
    ]


FAMILIES: dict[str, FamilySpec] = {
    LENZE_8400_MOTEC: FamilySpec(
        key=LENZE_8400_MOTEC,
        name="Lenze 8400 motec CANopen communication unit (E84DGFCxxx)",
        manual=_M8400,
        # Figure 6-1 is not in the manual text; drawn in the order of the tables in §6.3.1 / §6.3.2.
        switches=[Switch(label=lab, role="baud") for lab in ("c", "b", "a")]
        + [Switch(label=str(w), role="address", weight=w) for w in (64, 32, 16, 8, 4, 2, 1)],
        # §6.3.1 table, columns c b a
        baud_table=_rows(
            ("c", "b", "a"),
            {20: "101", 50: "011", 125: "010", 250: "001", 500: "000", 800: "110", 1000: "100"},
        ),
        switch_node_range=(1, 63),
        code_node_range=(1, 63),
        baud_rates_kbit=[20, 50, 125, 250, 500, 800, 1000],
        node_code="C00350",
        baud_code="C00351",
        # C00351 selection list (§12.2)
        baud_code_values={500: 0, 250: 1, 125: 2, 50: 3, 1000: 4, 20: 5, 800: 14},
        lenze_setting="All switches OFF (§6.3): node address from C00350 (Lenze setting 1), "
        "baud rate from C00351 (0 = 500 kbit/s).",
        rules=[
            "§6.3.2: node address = sum of the values of the address switches in ON position.",
            "§6.3.2: all address switches 1 … 64 OFF -> node address from C00350 (C00350 can only be "
            "parameterised if the DIP switches give node address 0).",
            "§6.3.2: switch 64 ON (node address > 63) -> node address 63 is always used.",
            "§12.2 C00351: the baud rate can only be parameterised if the DIP switches give baud rate 0 "
            "(a, b, c OFF).",
            "§6.3: the DIP switches are read only at switch-on; C00349 shows what was read.",
            "§12.2: changes of C00350/C00351 take effect after CAN reset node (C00002/26).",
        ],
        ambiguities=[
            "§12.2 C00349 names bits 7/8/9 'Baud rate 1/2/4' but the manual never says which of the switches "
            "a/b/c is bit 7 (the low bit); this tool assumes a = 1, b = 2, c = 4 (then the DIP code equals "
            "the C00351 value for every baud rate except 800 kbit/s, where the switch code is 6 and C00351 "
            "is 14). It only affects the C00349 read-back value, not the baud rate the §6.3.1 table gives.",
            "§12.2 C00349 bit 15 'Accept DIP switch at 24V-ON' is not explained further; as the display is 'the "
            "DIP switch setting at the last mains connection', this tool sets it in every read-back (the "
            "switches are read at 24 V on, also when they are all OFF and the codes apply).",
            "§6.3.1 vs §12.2: a, b, c OFF is printed as '500 kbps' in the switch table while C00351 says the "
            "code applies when the switches give baud rate 0; both hold with C00351 = 0 (500 kbit/s), the "
            "Lenze setting (bold print lost in the text). With a, b, c OFF this tool reports the baud rate "
            "of C00351.",
            "§6.3.2 note says 'The valid address range is 0 … 63'; everywhere else 1 … 63 (0 = use C00350).",
            "§6.3.1: c, b, a all ON is not in the table; the device's behaviour for it is not stated.",
            "§8.3 short overview prints the Lenze setting of C00353 as '0: COBID = C0350 + CANBaseID' (the number "
            "of the Lenze base IDs, the text of the CANopen ones); §12.2 C00353 says Lenze setting 1 = CANBaseID, "
            "and the C00354 defaults (RPDO2 0x301) agree. This tool follows §12.2: CANopen base IDs are the "
            "Lenze setting, the Lenze base IDs (RPDO2 0x281 + node id) need C00353 = 0.",
        ],
    ),
    LENZE_EMF2178IB: FamilySpec(
        key=LENZE_EMF2178IB,
        name="Lenze EMF2178IB CANopen communication module (8200 vector / 93XX / ECS / Drive PLC)",
        manual=_MEMF,
        switches=[Switch(label=f"S{n}", role="address", weight=2 ** (7 - n)) for n in range(1, 8)]
        + [Switch(label=f"S{n}", role="baud") for n in (8, 9, 10)],
        # §6.3 "Baud rate setting" table, columns S8 S9 S10
        baud_table=_rows(
            ("S8", "S9", "S10"),
            {10: "110", 20: "101", 50: "011", 125: "010", 250: "001", 500: "000", 1000: "100"},
        ),
        switch_node_range=(1, 127),
        code_node_range=(1, 99),
        baud_rates_kbit=[10, 20, 50, 125, 250, 500, 1000],
        node_code="C1850",
        baud_code="C1851",
        baud_code_values={50: None, 125: None, 250: None, 500: None, 1000: None},
        lenze_setting="All switches OFF (§6.3): node address from C1850/C2350, baud rate from C1851/C2351.",
        rules=[
            "§6.3: node address = sum of the values of switches 1 … 7 in ON position (S1 = 64 … S7 = 1).",
            "§6.3: with address switches 1 … 7 OFF (Lenze setting) node address and baud rate are taken from "
            "C1850/C2350 and C1851/C2351; the baud switches 8 … 10 are then ignored.",
            "§6.3: the codes are inactive if at least one address switch is ON at mains connection.",
            "§6.3: node addresses > 99 can only be set via DIP switch; 10 and 20 kbit/s only via DIP switch.",
            "§7: C18xx codes for 8200 vector / 93XX (EVS93xx-ES/EP/EK/ER, EVF93xx-EV, E82EVxxx); C23xx for "
            "9300 Servo PLC, Drive PLC, ECS (EVS93xx-EI/ET, EPL-10200, ECSxS/P/M/A).",
            "§6.3: switch changes take effect after switching the module's supply off and on.",
            "§6.3: changed C1850/C2350 and C1851/C2351 are accepted by switching the supply off and on, 'Reset "
            "node' with C0358 = 1, the NMT command 'Reset Communication', or C2120 (AIF control byte) = 1 "
            "(C2120 is described for 9300 Servo PLC / Drive PLC / ECS, §10.6.2).",
        ],
        ambiguities=[
            "The selection values of C1851/C2351 are in chapter 14, which the available manual text lacks "
            "(it ends in §13.2.8); only the baud rate is shown, not the code value.",
            "§6.3: S10 … S8 correspond to the EMF2172IB's S1 … S3, but the manual does not say whether the "
            "ON/OFF codes are the same; do not copy EMF2172IB baud settings.",
            "§6.3: S8, S9, S10 all ON is not in the table; the device's behaviour for it is not stated.",
        ],
    ),
    SIEMENS_MM4: FamilySpec(
        key=SIEMENS_MM4,
        name="Siemens MICROMASTER 420/430/440 CANopen option module",
        manual=_MMM4,
        code_node_range=(1, 127),
        baud_rates_kbit=[10, 20, 50, 125, 250, 500, 800, 1000],
        node_code="P0918",
        baud_code="P2010",
        baud_code_values={k: k for k in (10, 20, 50, 125, 250, 500, 800, 1000)},
        lenze_setting="No DIP switches. Factory setting P0918 = 3 (node id), P2010 = 10 (kbit/s).",
        rules=[
            "§5.2: P0918 (object 0x2396) = CANopen node id, default 3.",
            "§5.2: P2010 (object 0x27DA) = CANopen baud rate in kbit/s, default 10.",
            "§5.6 Table 5-1: hundreds digit of P2041.04 = baud rate: 0 = 10, 1 = 20, 2 = 50, 3 = 125, "
            "4 = 250, 5 = 500, 6 = 800, 7 = 1000 kbit/s, 8-9 not permissible.",
            "§5.2: changes of baud rate or node id take effect after power OFF/ON or NMT reset node; save "
            "with 0x1010.1 ('save').",
        ],
        ambiguities=[
            "§5.2 names P2010 (kbit/s) as the baud-rate parameter while §5.6 Table 5-1 encodes the baud rate "
            "in the hundreds digit of P2041.04 (and alarm remedies point to P2041.04); the manual does not "
            "explain how the two relate. Set both to the same baud rate.",
            "The manual does not print the range of P0918; CiA 301 node ids 1 … 127 are assumed.",
        ],
    ),
}

_ALIASES = {
    "8400-motec": LENZE_8400_MOTEC,
    "8400motec": LENZE_8400_MOTEC,
    "motec": LENZE_8400_MOTEC,
    "e84dgfc": LENZE_8400_MOTEC,
    "emf2178ib": LENZE_EMF2178IB,
    "emf2178": LENZE_EMF2178IB,
    "mm4": SIEMENS_MM4,
    "micromaster": SIEMENS_MM4,
    "siemens-micromaster": SIEMENS_MM4,
}


def resolve_family(name: str) -> str:
    """Map a family key, alias or profile id (``lenze-8400-motec-canopen``) to a family key."""
    key = name.strip().lower()
    if key in FAMILIES:
        return key
    if key in _ALIASES:
        return _ALIASES[key]
    if "ethercat" not in key and ("motec" in key or "e84dgfc" in key):
        return LENZE_8400_MOTEC
    if "emf2178" in key:
        return LENZE_EMF2178IB
    if "micromaster" in key or "mm4" in key or "mm420" in key or "mm440" in key:
        return SIEMENS_MM4
    raise UnknownProfile(
        f"No switch/addressing data for device family '{name}'. Known families: {', '.join(FAMILIES)}."
    )


def family_spec(name: str) -> FamilySpec:
    return FAMILIES[resolve_family(name)]


class DipResult(BaseModel):
    family: str
    switches: dict[str, bool]
    address_switch_sum: int
    """Sum of the weights of the ON address switches (what C00349 shows as address)."""
    baud_switch_kbit: int | None
    """Baud rate the baud switches select by the manual's table (None: pattern not in the table)."""
    node_id: int | None
    node_id_source: str
    """``switches`` or the parameter (``C00350``, ``C1850/C2350``, ``P0918``) the node id comes from."""
    baud_kbit: int | None
    baud_source: str
    summary: str
    rules_applied: list[str] = Field(default_factory=list)
    problems: list[str] = Field(default_factory=list)
    alternative: list[ParameterSetting] = Field(default_factory=list)
    """Parameter values that give the same node id and baud rate without switches (where possible)."""
    readback: dict[str, int] = Field(default_factory=dict)
    """Value the device's switch read-back parameter would show (8400 motec C00349)."""
    ambiguities: list[str] = Field(default_factory=list)


class NotSettableBySwitches(InvalidValue):
    """The node id / baud rate exists for the device but the switches cannot set it."""

    title = N_("Not settable by DIP switches")

    def __init__(self, detail: str, *, alternative: list[ParameterSetting]) -> None:
        super().__init__(detail)
        self.alternative = alternative

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "alternative": [a.model_dump() for a in self.alternative]}


def _normalise(spec: FamilySpec, switches: dict[str, bool]) -> dict[str, bool]:
    known = {s.label.lower(): s.label for s in spec.switches}
    result = {s.label: False for s in spec.switches}
    for label, on in switches.items():
        key = str(label).strip().lower()
        if key not in known:
            raise InvalidValue(
                f"{spec.name} has no switch '{label}'. Switches: "
                f"{', '.join(s.label for s in spec.switches) or 'none'}."
            )
        result[known[key]] = bool(on)
    return result


def _baud_from_switches(spec: FamilySpec, positions: dict[str, bool]) -> int | None:
    for row in spec.baud_table:
        if all(positions[label] == on for label, on in row.positions.items()):
            return row.baud_kbit
    return None


def _check_baud(spec: FamilySpec, baud_kbit: int) -> None:
    if baud_kbit not in spec.baud_rates_kbit:
        raise InvalidValue(
            f"{spec.name} does not support {baud_kbit} kbit/s. Baud rates: "
            f"{', '.join(str(b) for b in spec.baud_rates_kbit)} kbit/s."
        )


# P2041.04 digits below the baud rate (§5.6 Table 5-1) in the factory setting: 0x6007 and 0x1029.1 default to 0.
_P2041_04_TENS = 0
_P2041_04_ONES = 0


def code_alternative(family: str, node_id: int, baud_kbit: int) -> list[ParameterSetting]:
    """Parameter values that set ``node_id`` and ``baud_kbit`` without switches (a note says where
    impossible)."""
    spec = family_spec(family)
    lo, hi = spec.code_node_range
    settings: list[ParameterSetting] = []
    if spec.key == LENZE_8400_MOTEC:
        settings.append(
            ParameterSetting(
                code="C00350",
                value=node_id,
                meaning=f"node address {node_id}",
                note="DIP switches 1 … 64 must all be OFF; effective after CAN reset node (C00002/26).",
            )
        )
        settings.append(
            ParameterSetting(
                code="C00351",
                value=spec.baud_code_values.get(baud_kbit),
                meaning=f"{baud_kbit} kbit/s",
                note="DIP switches a, b, c must all be OFF (baud rate 0); effective "
                "after CAN reset node (C00002/26).",
            )
        )
    elif spec.key == LENZE_EMF2178IB:
        node_ok = lo <= node_id <= hi
        settings.append(
            ParameterSetting(
                code="C1850/C2350",
                value=node_id if node_ok else None,
                meaning=f"node address {node_id}",
                note=(
                    "All address switches 1 … 7 OFF. C1850 for 8200 vector/93XX, C2350 for Servo PLC/Drive "
                    "PLC/ECS."
                    if node_ok
                    else "Not possible: node addresses > 99 only via DIP switch (§6.3)."
                ),
            )
        )
        baud_ok = baud_kbit not in (10, 20)
        settings.append(
            ParameterSetting(
                code="C1851/C2351",
                value=None,
                meaning=f"{baud_kbit} kbit/s",
                note=(
                    "Selection value in chapter 14 (not in the available manual text)."
                    if baud_ok
                    else "Not possible: 10 and 20 kbit/s only via DIP switch (§6.3)."
                ),
            )
        )
    else:
        settings.append(
            ParameterSetting(
                code="P0918",
                value=node_id,
                meaning=f"node id {node_id}",
                note="Object 0x2396; effective after power OFF/ON or NMT reset node.",
            )
        )
        settings.append(
            ParameterSetting(
                code="P2010",
                value=baud_kbit,
                meaning=f"{baud_kbit} kbit/s",
                note="Object 0x27DA, value in kbit/s.",
            )
        )
        digit = spec.baud_rates_kbit.index(baud_kbit)
        settings.append(
            ParameterSetting(
                code="P2041.04",
                value=100 * digit + 10 * _P2041_04_TENS + _P2041_04_ONES,
                meaning=f"hundreds digit {digit} = {baud_kbit} kbit/s, tens digit {_P2041_04_TENS} = drive "
                f"reaction to a communication error (0x6007), ones digit {_P2041_04_ONES} = CAN state machine "
                "reaction (0x1029.1)",
                note="The whole decimal number is written (§5.6 Table 5-1, example 432 = 250 kbit/s); tens and "
                "ones are the factory reactions (0x6007 = 0 no action, 0x1029.1 = 0 pre-operational). "
                "Writing the hundreds digit alone would select 10 kbit/s.",
            )
        )
    return settings


C00349_ACCEPTED_AT_24V_ON = 1 << 15


def _c00349(spec: FamilySpec, positions: dict[str, bool]) -> int:
    """8400 motec C00349 after switch-on: bits 0-6 address switches, bits 7-9 baud 1/2/4 (assumed a = 1, b = 2,
    c = 4), bit 15 "Accept DIP switch at 24V-ON" (§12.2: the display shows the setting read at the last mains
    connection, so the switches were taken over at 24 V on)."""
    value = sum(1 << bit for bit, w in enumerate((1, 2, 4, 8, 16, 32, 64)) if positions[str(w)])
    for bit, label in ((7, "a"), (8, "b"), (9, "c")):
        if positions[label]:
            value |= 1 << bit
    return value | C00349_ACCEPTED_AT_24V_ON


def decode(
    family: str,
    switches: dict[str, bool],
    *,
    code_node_id: int | None = None,
    code_baud_kbit: int | None = None,
) -> DipResult:
    """What the device uses with these switch positions.

    ``code_node_id``/``code_baud_kbit`` are the values in the node-address/baud-rate parameters
    (C00350/C00351,
    C1850/C1851, P0918/P2010); the Lenze/factory setting is assumed where the manual gives it.
    """
    spec = family_spec(family)
    if spec.key == SIEMENS_MM4:
        return _decode_mm4(spec, switches, code_node_id, code_baud_kbit)
    positions = _normalise(spec, switches)
    total = sum(s.weight or 0 for s in spec.address_switches if positions[s.label])
    baud_switch = _baud_from_switches(spec, positions)
    if spec.key == LENZE_8400_MOTEC:
        return _decode_8400(spec, positions, total, baud_switch, code_node_id, code_baud_kbit)
    return _decode_emf(spec, positions, total, baud_switch, code_node_id, code_baud_kbit)


def _decode_8400(
    spec: FamilySpec,
    positions: dict[str, bool],
    total: int,
    baud_switch: int | None,
    code_node_id: int | None,
    code_baud_kbit: int | None,
) -> DipResult:
    rules: list[str] = []
    problems: list[str] = []
    if total == 0:
        node_id: int | None = 1 if code_node_id is None else code_node_id
        node_source = "C00350"
        rules.append(spec.rules[1])
        if code_node_id is None:
            rules.append("C00350 Lenze setting: 1.")
        elif not 1 <= code_node_id <= 63:
            problems.append(f"C00350 = {code_node_id} is outside its range 1 … 63.")
    elif positions["64"]:
        node_id, node_source = 63, "switches"
        rules.append(spec.rules[2])
    else:
        node_id, node_source = total, "switches"
        rules.append(spec.rules[0])
    if baud_switch is None:
        baud: int | None = None
        baud_source = "switches"
        problems.append("Baud switches c, b, a all ON: this position is not in the §6.3.1 table.")
    elif baud_switch == 500:
        baud = 500 if code_baud_kbit is None else code_baud_kbit
        baud_source = "C00351"
        rules.append(spec.rules[3])
        if code_baud_kbit is not None and code_baud_kbit not in spec.baud_code_values:
            problems.append(f"{code_baud_kbit} kbit/s is not in the C00351 selection list.")
    else:
        baud, baud_source = baud_switch, "switches"
    return _result(
        spec,
        positions,
        total,
        baud_switch,
        node_id,
        node_source,
        baud,
        baud_source,
        rules,
        problems,
        readback={"C00349": _c00349(spec, positions)},
    )


def _decode_emf(
    spec: FamilySpec,
    positions: dict[str, bool],
    total: int,
    baud_switch: int | None,
    code_node_id: int | None,
    code_baud_kbit: int | None,
) -> DipResult:
    rules: list[str] = []
    problems: list[str] = []
    if total == 0:
        node_id, node_source = code_node_id, "C1850/C2350"
        baud, baud_source = code_baud_kbit, "C1851/C2351"
        rules += [spec.rules[1], spec.rules[6]]
        if code_node_id is not None and not 1 <= code_node_id <= 99:
            problems.append(
                f"C1850/C2350 = {code_node_id}: node addresses > 99 only via DIP switch; "
                "the module flashes LED 0 red twice (value not accepted)."
            )
        if code_baud_kbit in (10, 20):
            problems.append(f"{code_baud_kbit} kbit/s can only be selected via DIP switch.")
    else:
        node_id, node_source = total, "switches"
        rules.append(spec.rules[0])
        rules.append(spec.rules[2])
        baud, baud_source = baud_switch, "switches"
        if baud_switch is None:
            problems.append("Baud switches S8, S9, S10 all ON: this position is not in the §6.3 table.")
    return _result(
        spec,
        positions,
        total,
        baud_switch,
        node_id,
        node_source,
        baud,
        baud_source,
        rules,
        problems,
        readback={},
    )


def _decode_mm4(
    spec: FamilySpec, switches: dict[str, bool], code_node_id: int | None, code_baud_kbit: int | None
) -> DipResult:
    if switches:
        raise InvalidValue(f"{spec.name} has no DIP switches; set P0918 and P2010 instead.")
    node_id = 3 if code_node_id is None else code_node_id
    baud = 10 if code_baud_kbit is None else code_baud_kbit
    problems = []
    if not 1 <= node_id <= 127:
        problems.append(f"P0918 = {node_id} is not a CANopen node id (1 … 127).")
    if baud not in spec.baud_rates_kbit:
        problems.append(f"P2010 = {baud} is not a supported baud rate.")
    return _result(spec, {}, 0, None, node_id, "P0918", baud, "P2010", spec.rules[:3], problems, readback={})


def _result(
    spec: FamilySpec,
    positions: dict[str, bool],
    total: int,
    baud_switch: int | None,
    node_id: int | None,
    node_source: str,
    baud: int | None,
    baud_source: str,
    rules: list[str],
    problems: list[str],
    *,
    readback: dict[str, int],
) -> DipResult:
    node_text = "unknown (value of the parameter not given)" if node_id is None else str(node_id)
    baud_text = "unknown" if baud is None else f"{baud} kbit/s"
    summary = f"Node id {node_text} (from {node_source}), baud rate {baud_text} (from {baud_source})."
    alternative = (
        code_alternative(spec.key, node_id, baud)
        if node_id is not None and baud is not None and baud in spec.baud_rates_kbit
        else []
    )
    return DipResult(
        family=spec.key,
        switches=positions,
        address_switch_sum=total,
        baud_switch_kbit=baud_switch,
        node_id=node_id,
        node_id_source=node_source,
        baud_kbit=baud,
        baud_source=baud_source,
        summary=summary,
        rules_applied=rules,
        problems=problems,
        alternative=alternative,
        readback=readback,
        ambiguities=list(spec.ambiguities),
    )


def encode(family: str, node_id: int, baud_kbit: int) -> DipResult:
    """Switch positions for ``node_id`` at ``baud_kbit`` (MICROMASTER: parameter values), checked by decoding.

    Raises OutOfRange for a node id the device cannot use at all, NotSettableBySwitches (with the parameter
    alternative) for one only its parameters can set, InvalidValue for an unsupported baud rate.
    """
    spec = family_spec(family)
    _check_baud(spec, baud_kbit)
    if spec.key == SIEMENS_MM4:
        lo, hi = spec.code_node_range
        if not lo <= node_id <= hi:
            raise OutOfRange(f"Node id {node_id} is outside {lo} … {hi}.")
        return decode(spec.key, {}, code_node_id=node_id, code_baud_kbit=baud_kbit)
    assert spec.switch_node_range is not None
    lo, hi = spec.switch_node_range
    if not lo <= node_id <= hi:
        clo, chi = spec.code_node_range
        if clo <= node_id <= chi:
            raise NotSettableBySwitches(
                f"Node id {node_id} cannot be set by the switches of {spec.name}.",
                alternative=code_alternative(spec.key, node_id, baud_kbit),
            )
        raise OutOfRange(f"{spec.name}: node id {node_id} is outside {lo} … {hi}.")
    positions = {s.label: bool(node_id & (s.weight or 0)) for s in spec.address_switches}
    row = next(r for r in spec.baud_table if r.baud_kbit == baud_kbit)
    positions.update(row.positions)
    result = decode(spec.key, positions, code_baud_kbit=baud_kbit)
    assert result.node_id == node_id and result.baud_kbit == baud_kbit
    return result
