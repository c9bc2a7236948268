"""DIP-switch calculator against the manuals' tables and examples (8400 motec §6.3, EMF2178IB §6.3), evaluating the
shipped profiles' ``switches`` sections."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivebench.device.calculators.dip import NotSettableBySwitches, decode, encode
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import InvalidValue, OutOfRange, UnknownProfile
from tests.conftest import shipped_switch_devices

DEVICES = shipped_switch_devices()
FAMILIES = {device.spec.key: device for device in DEVICES.all()}
M8400 = DEVICES.get("lenze-8400-motec")
EMF = DEVICES.get("lenze-emf2178ib")
SIEMENS_MM4 = DEVICES.get("siemens-mm4")


def on(*labels: str) -> dict[str, bool]:
    return dict.fromkeys(labels, True)


# --- 8400 motec ---------------------------------------------------------------------------------------------
def test_8400_manual_example_16_4_2_1_is_23() -> None:
    result = decode(M8400, on("16", "4", "2", "1", "a"))
    assert (result.node_id, result.node_id_source) == (23, "switches")
    assert result.address_switch_sum == 23
    assert result.readback["C00349"] == 23 | (1 << 7) | (1 << 15)


@pytest.mark.parametrize("switches", [(), ("1",), ("64", "c", "b", "a"), ("32", "b")])
def test_8400_c00349_bit_15_accept_dip_switch_at_24v_on(switches: tuple[str, ...]) -> None:
    """§12.2 C00349: 'Display of the DIP switch setting at the last mains connection', bit 15 'Accept DIP switch at
    24V-ON': the read-back after switch-on has bit 15 set, bits 10 ... 14 (reserved) clear."""
    value = decode(M8400, on(*switches)).readback["C00349"]
    assert value & 0x8000 and not value & 0x7C00


def test_8400_all_off_uses_c00350_and_c00351() -> None:
    factory = decode(M8400, {})
    assert (factory.node_id, factory.node_id_source) == (1, "C00350")  # C00350 Lenze setting 1
    assert (factory.baud_kbit, factory.baud_source) == (500, "C00351")
    configured = decode(M8400, {}, code_node_id=42, code_baud_kbit=800)
    assert (configured.node_id, configured.baud_kbit) == (42, 800)
    assert [(a.code, a.value) for a in configured.alternative] == [("C00350", 42), ("C00351", 14)]


def test_8400_baud_switches_set_ignore_c00351() -> None:
    result = decode(M8400, on("1", "c"), code_baud_kbit=125)
    assert (result.baud_kbit, result.baud_source) == (1000, "switches")


@pytest.mark.parametrize("others", [(), ("1",), ("32", "16", "8", "4", "2", "1"), ("2", "8")])
def test_8400_switch_64_on_always_gives_63(others: tuple[str, ...]) -> None:
    result = decode(M8400, on("64", *others))
    assert (result.node_id, result.node_id_source) == (63, "switches")
    assert any("63 is always used" in rule for rule in result.rules_applied)


# §6.3.1 table, every row: (c, b, a) -> kbit/s
BAUD_8400 = [
    ((1, 0, 1), 20),
    ((0, 1, 1), 50),
    ((0, 1, 0), 125),
    ((0, 0, 1), 250),
    ((0, 0, 0), 500),
    ((1, 1, 0), 800),
    ((1, 0, 0), 1000),
]


@pytest.mark.parametrize(("cba", "kbit"), BAUD_8400)
def test_8400_baud_table_rows(cba: tuple[int, int, int], kbit: int) -> None:
    switches = {"c": bool(cba[0]), "b": bool(cba[1]), "a": bool(cba[2]), "4": True, "1": True}
    result = decode(M8400, switches, code_baud_kbit=500)
    assert result.baud_switch_kbit == kbit
    assert result.baud_kbit == kbit
    assert result.baud_source == ("C00351" if kbit == 500 else "switches")
    encoded = encode(M8400, 5, kbit).switches
    assert {k: encoded[k] for k in "cba"} == {k: switches[k] for k in "cba"}


def test_8400_unlisted_baud_pattern_is_a_problem() -> None:
    result = decode(M8400, on("c", "b", "a", "1"))
    assert result.baud_kbit is None
    assert result.problems and "not in the §6.3.1 table" in result.problems[0]


def test_8400_c00349_readback_assumes_a_is_low_bit_and_says_so() -> None:
    result = decode(M8400, on("c", "b", "2"))  # 800 kbit/s
    assert result.readback["C00349"] == 2 | (1 << 8) | (1 << 9) | (1 << 15)
    assert any("which of the switches a/b/c is bit 7" in text for text in result.ambiguities)


def test_8400_c00353_lenze_setting_follows_12_2_and_says_so(registry: ProfileRegistry) -> None:
    """§8.3's short overview and §12.2 disagree on the Lenze setting of C00353; the page names the conflict and
    the profile holds the §12.2 reading the COB-ID table uses (CANopen base IDs, RPDO2 = 0x300 + node id)."""
    assert any("C00353" in text and "§12.2" in text for text in decode(M8400, {}).ambiguities)
    catalog = Catalog(registry.get("lenze-8400-motec-canopen"))
    assert [catalog.resolve(ref).entry.default for ref in ("C00353/1", "C00353/2", "C00354/3")] == [1, 1, 0x301]


# Chapter 14 lists all 63 combinations: the 7-bit binary form of the address with switch 64 OFF.
@pytest.mark.parametrize("address", range(1, 64))
def test_8400_chapter_14_address_rows(address: int) -> None:
    switches = encode(M8400, address, 250).switches
    expected = {str(w): bool(address & w) for w in (64, 32, 16, 8, 4, 2, 1)}
    assert {k: switches[k] for k in expected} == expected
    assert decode(M8400, switches).node_id == address


def test_8400_node_64_cannot_be_used() -> None:
    with pytest.raises(OutOfRange):
        encode(M8400, 64, 500)
    with pytest.raises(InvalidValue):
        encode(M8400, 5, 10)


# --- EMF2178IB ----------------------------------------------------------------------------------------------
def test_emf_manual_example_s3_s5_s6_s7_is_23() -> None:
    result = decode(EMF, on("S3", "S5", "S6", "S7"))
    assert (result.node_id, result.node_id_source) == (23, "switches")
    assert (result.baud_kbit, result.baud_source) == (500, "switches")


@pytest.mark.parametrize(("switch", "weight"), [(f"S{n}", 2 ** (7 - n)) for n in range(1, 8)])
def test_emf_address_weights(switch: str, weight: int) -> None:
    assert decode(EMF, on(switch)).node_id == weight


# §6.3 baud table, every row: (S8, S9, S10) -> kbit/s
BAUD_EMF = [
    ((1, 1, 0), 10),
    ((1, 0, 1), 20),
    ((0, 1, 1), 50),
    ((0, 1, 0), 125),
    ((0, 0, 1), 250),
    ((0, 0, 0), 500),
    ((1, 0, 0), 1000),
]


@pytest.mark.parametrize(("bits", "kbit"), BAUD_EMF)
def test_emf_baud_table_rows(bits: tuple[int, int, int], kbit: int) -> None:
    switches = {"S8": bool(bits[0]), "S9": bool(bits[1]), "S10": bool(bits[2]), "S7": True}
    assert decode(EMF, switches).baud_kbit == kbit
    encoded = encode(EMF, 1, kbit).switches
    assert (encoded["S8"], encoded["S9"], encoded["S10"]) == tuple(map(bool, bits))


def test_emf_all_address_off_takes_codes_and_ignores_baud_switches() -> None:
    result = decode(EMF, on("S8"), code_node_id=12, code_baud_kbit=250)
    assert (result.node_id, result.node_id_source) == (12, "C1850/C2350")
    assert (result.baud_kbit, result.baud_source) == (250, "C1851/C2351")
    unknown = decode(EMF, {})
    assert unknown.node_id is None and unknown.baud_kbit is None


def test_emf_codes_cannot_give_100_or_10_kbit() -> None:
    result = decode(EMF, {}, code_node_id=100, code_baud_kbit=10)
    assert len(result.problems) == 2
    alt = encode(EMF, 100, 10).alternative
    assert alt[0].value is None and "> 99 only via DIP" in (alt[0].note or "")
    assert "only via DIP" in (alt[1].note or "")


# --- MICROMASTER --------------------------------------------------------------------------------------------
def test_emf_rules_say_how_changed_codes_take_effect() -> None:
    """§6.3: C1850/C2350, C1851/C2351 changes are accepted by power off/on, C0358 = 1, NMT 'Reset Communication',
    C2120 = 1; the C18xx/C23xx device split is §7 ('Activate the 2. SDO channel')."""
    rules = decode(EMF, {}, code_node_id=5, code_baud_kbit=500).rules_applied
    accept = next(rule for rule in rules if "accepted by" in rule)
    assert all(part in accept for part in ("off and on", "C0358 = 1", "Reset Communication", "C2120"))
    split = next(rule.text for rule in EMF.spec.rules if "C23xx" in rule.text)
    assert split.startswith("§7:")


def test_mm4_has_no_switches_and_gives_parameters() -> None:
    assert SIEMENS_MM4.spec.switches == []
    result = encode(SIEMENS_MM4, 4, 250)
    settings = {a.code: a.value for a in result.alternative}
    assert settings == {"P0918": 4, "P2010": 250, "P2041.04": 400}  # §5.6: hundreds digit 4 = 250 kbit/s
    factory = decode(SIEMENS_MM4, {})
    assert (factory.node_id, factory.baud_kbit) == (3, 10)
    assert any("P2041.04" in a for a in factory.ambiguities)
    with pytest.raises(InvalidValue):
        decode(SIEMENS_MM4, {"1": True})


def test_unknown_switch_and_family() -> None:
    with pytest.raises(InvalidValue):
        decode(M8400, {"S1": True})
    with pytest.raises(UnknownProfile):
        DEVICES.get("acme-drive")
    assert DEVICES.get("lenze-8400-motec-canopen") == M8400
    assert DEVICES.get("EMF2178IB") == EMF
    assert DEVICES.get("lenze-93xx-emf2178ib") == EMF  # both EMF2178IB profiles carry the module's section


def test_not_settable_by_switches_carries_alternative() -> None:
    err = NotSettableBySwitches("x", alternative=encode(M8400, 3, 500).alternative)
    assert err.extra()["alternative"][0]["code"] == "C00350"


# --- round trips --------------------------------------------------------------------------------------------
SWITCH_FAMILIES = [k for k, device in FAMILIES.items() if device.spec.switches]


@given(st.sampled_from(SWITCH_FAMILIES), st.data())
def test_address_switches_address_round_trip(family: str, data: st.DataObject) -> None:
    device = FAMILIES[family]
    spec = device.spec
    assert spec.switch_node_range is not None
    node = data.draw(st.integers(*spec.switch_node_range))
    baud = data.draw(st.sampled_from([r.baud_kbit for r in spec.baud_table]))
    first = encode(device, node, baud)
    assert (first.node_id, first.baud_kbit) == (node, baud)
    again = decode(device, first.switches, code_baud_kbit=baud)
    assert again.switches == first.switches
    assert encode(device, again.node_id or 0, again.baud_kbit or 0).switches == first.switches


@given(st.sampled_from(SWITCH_FAMILIES), st.data())
def test_any_switch_setting_re_encodes_to_the_same_result(family: str, data: st.DataObject) -> None:
    device = FAMILIES[family]
    switches = {s.label: data.draw(st.booleans()) for s in device.spec.switches}
    result = decode(device, switches, code_node_id=7, code_baud_kbit=125)
    if result.node_id_source != "switches" or result.baud_kbit is None:
        return
    again = decode(
        device,
        encode(device, result.node_id or 0, result.baud_kbit).switches,
        code_baud_kbit=result.baud_kbit,
    )
    assert (again.node_id, again.baud_kbit) == (result.node_id, result.baud_kbit)


@pytest.mark.parametrize(
    ("family", "node"),
    [(f, n) for f in SWITCH_FAMILIES for n in range(1, (FAMILIES[f].spec.switch_node_range or (0, 0))[1] + 1)],
)
def test_every_valid_address_round_trips(family: str, node: int) -> None:
    device = FAMILIES[family]
    switches = encode(device, node, 500).switches
    assert decode(device, switches, code_baud_kbit=500).node_id == node
    assert sum(s.weight or 0 for s in device.spec.address_switches if switches[s.label]) == node


# --- rows of the parameter tables ----------------------------------------------------------------------------------
# 8400 motec §12.2 C00351 selection list, every row: value -> kbit/s
C00351_ROWS = [(0, 500), (1, 250), (2, 125), (3, 50), (4, 1000), (5, 20), (14, 800)]


@pytest.mark.parametrize(("value", "kbit"), C00351_ROWS)
def test_8400_c00351_selection_list_rows(value: int, kbit: int) -> None:
    result = decode(M8400, {}, code_node_id=7, code_baud_kbit=kbit)  # a, b, c OFF: the baud rate is C00351's
    assert (result.baud_kbit, result.baud_source) == (kbit, "C00351")
    assert {a.code: a.value for a in result.alternative} == {"C00350": 7, "C00351": value}


# MICROMASTER §5.6 Table 5-1, P2041.04 hundreds digit, every row: digit -> kbit/s (8 and 9 are not permissible)
P2041_ROWS = [(0, 10), (1, 20), (2, 50), (3, 125), (4, 250), (5, 500), (6, 800), (7, 1000)]


@pytest.mark.parametrize(("digit", "kbit"), P2041_ROWS)
def test_mm4_p2041_04_is_the_whole_number_per_baud_rate(digit: int, kbit: int) -> None:
    """The value to write is the whole decimal number: hundreds = baud rate, tens/ones = the factory reactions to a
    communication error (0x6007 = 0, 0x1029.1 = 0). The hundreds digit alone (4 for 250 kbit/s) would select
    10 kbit/s with ones digit 4, which 0x1029.1 does not define."""
    setting = next(a for a in encode(SIEMENS_MM4, 3, kbit).alternative if a.code == "P2041.04")
    assert setting.value == 100 * digit
    assert (setting.value // 100, setting.value // 10 % 10, setting.value % 10) == (digit, 0, 0)
    assert f"{kbit} kbit/s" in setting.meaning


def test_mm4_p2041_04_worked_example_432() -> None:
    """§5.6: 250 kbit/s -> hundreds digit 4 of the example's P2041.04 = 432; the calculator keeps tens/ones 0."""
    value = next(a.value for a in encode(SIEMENS_MM4, 3, 250).alternative if a.code == "P2041.04")
    assert value is not None and value // 100 == 432 // 100 and value == 400


def test_mm4_unsupported_values() -> None:
    with pytest.raises(OutOfRange):
        encode(SIEMENS_MM4, 128, 500)
    with pytest.raises(InvalidValue):
        encode(SIEMENS_MM4, 3, 100)
    assert decode(SIEMENS_MM4, {}, code_node_id=0).problems


@given(st.integers(1, 127), st.sampled_from(SIEMENS_MM4.spec.baud_rates_kbit))
def test_mm4_parameters_round_trip(node: int, baud: int) -> None:
    """MICROMASTER has no switches: node id and baud rate -> P0918/P2010 -> the same node id and baud rate."""
    settings = {a.code: a.value for a in encode(SIEMENS_MM4, node, baud).alternative}
    again = decode(SIEMENS_MM4, {}, code_node_id=settings["P0918"], code_baud_kbit=settings["P2010"])
    assert (again.node_id, again.baud_kbit, again.problems) == (node, baud, [])
