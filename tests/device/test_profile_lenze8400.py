"""The shipped Lenze 8400 profiles (motec CANopen communication unit, BaseLine C) against their manuals.

Indices, scaling and selection texts are the manuals' (seed 000: communication manual 8400 motec CANopen,
chapters 9, 12, 13; seed 002: 8400 BaseLine C reference manual, table of contents of the parameter list).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from drivebench.config import settings
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Access, ObjectEntry, Parameter, Profile
from drivebench.device.profiles.scaling import from_raw, to_raw
from drivebench.errors import InvalidValue, OutOfRange, ReadOnly, UnknownParameter
from drivebench.protocol.datatypes import DataType

MOTEC = "lenze-8400-motec-canopen"
BASELINE = "lenze-8400-baseline-c"

# Chapter 12.2 "table of attributes": code -> index printed by the manual (all equal 0x5FFF - code).
CAN_CODE_INDEX = {
    "C00322": 0x5EBD, "C00323": 0x5EBC, "C00324": 0x5EBB, "C00345": 0x5EA6, "C00347": 0x5EA4, "C00349": 0x5EA2,
    "C00350": 0x5EA1, "C00351": 0x5EA0, "C00352": 0x5E9F, "C00353": 0x5E9E, "C00354": 0x5E9D, "C00355": 0x5E9C,
    "C00356": 0x5E9B, "C00357": 0x5E9A, "C00359": 0x5E98, "C00360": 0x5E97, "C00364": 0x5E93, "C00366": 0x5E91,
    "C00367": 0x5E90, "C00368": 0x5E8F, "C00369": 0x5E8E, "C00372": 0x5E8B, "C00381": 0x5E82, "C00385": 0x5E7E,
    "C00386": 0x5E7D, "C00389": 0x5E7A, "C00409": 0x5E66, "C00592": 0x5DAF, "C00593": 0x5DAE,
}
# Number of subcodes ("DA" column; 1 = single variable, subcode 0) of the CAN codes.
CAN_CODE_SUBCODES = {
    "C00322": 2, "C00323": 2, "C00324": 3, "C00347": 1, "C00353": 2, "C00354": 4, "C00355": 4, "C00356": 5,
    "C00357": 2, "C00360": 12, "C00372": 2, "C00385": 1, "C00386": 1, "C00389": 4, "C00409": 8, "C00592": 5,
    "C00593": 2,
}
# Chapter 13: every implemented object with its subindices.
MOTEC_OBJECTS = {
    0x1000: [0], 0x1001: [0], 0x1003: list(range(11)), 0x1005: [0], 0x1006: [0], 0x1014: [0], 0x1016: [0, 1],
    0x1017: [0], 0x1018: [0, 1, 2, 3, 4], 0x1200: [0, 1, 2], 0x1201: [0, 1, 2, 3], 0x1400: [0, 1, 2, 3, 5],
    0x1401: [0, 1, 2, 3, 5], 0x1600: [0, 1, 2, 3, 4], 0x1601: [0, 1, 2, 3, 4], 0x1800: [0, 1, 2, 3, 5],
    0x1801: [0, 1, 2, 3, 5], 0x1A00: [0, 1, 2, 3, 4], 0x1A01: [0, 1, 2, 3, 4],
}
# Seed 002: the 170 codes of the BaseLine C parameter list (10.2), in the manual's order.
_BASELINE_CODE_TEXT = """
00002 00003 00006 00007 00010 00011 00012 00013 00015 00016 00018 00019 00021 00022 00023 00024 00026 00027 00028
00029 00033 00034 00036 00039 00050 00051 00052 00053 00054 00056 00057 00058 00059 00061 00064 00066 00073 00074
00081 00084 00085 00087 00088 00089 00090 00091 00092 00093 00094 00095 00097 00098 00099 00100 00105 00106 00107
00114 00118 00120 00122 00123 00134 00136 00137 00141 00142 00144 00150 00155 00158 00159 00165 00166 00168 00169
00170 00173 00174 00177 00178 00179 00182 00200 00201 00203 00222 00223 00224 00225 00226 00227 00228 00231 00234
00242 00243 00244 00245 00322 00323 00324 00345 00347 00350 00351 00352 00353 00354 00355 00356 00357 00359 00360
00364 00366 00367 00368 00369 00372 00381 00385 00386 00389 00409 00443 00444 00470 00472 00480 00481 00482 00516
00517 00565 00574 00581 00592 00593 00594 00598 00600 00601 00604 00606 00620 00621 00700 00701 00725 00727 00728
00800 00801 00802 00803 00804 00805 00806 00830 00831 00833 00866 00868 00909 00910 00990 00991 00992 00994
"""
BASELINE_CODES = _BASELINE_CODE_TEXT.split()


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory) -> ProfileRegistry:
    return ProfileRegistry(settings.profiles_dir, tmp_path_factory.mktemp("no-uploads"))


@pytest.fixture(scope="module")
def motec(registry: ProfileRegistry) -> Profile:
    return registry.get(MOTEC)


@pytest.fixture(scope="module")
def baseline(registry: ProfileRegistry) -> Profile:
    return registry.get(BASELINE)


def _param(catalog: Catalog, ref: str) -> Parameter:
    entry = catalog.resolve(ref).entry
    assert isinstance(entry, Parameter)
    return entry


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
def test_profile_file_validates_and_loads_without_errors(registry: ProfileRegistry, profile_id: str) -> None:
    path = settings.profiles_dir / f"{profile_id}.json"
    assert Profile.model_validate_json(path.read_text(encoding="utf-8")).id == profile_id
    assert path.name not in {name for name, _ in registry.errors}
    assert registry.is_builtin(profile_id)


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
@pytest.mark.parametrize(("ref", "index", "sub"), [
    ("C00061", 0x5FC2, 0),  # 9.3.1: read heatsink temperature, 40 C2 5F 00
    ("C00088", 0x5FA7, 0),  # 9.3.2: write rated motor current, 23 A7 5F 00
    ("C88", 0x5FA7, 0),
    ("88", 0x5FA7, 0),
    ("C00099", 0x5F9C, 0),  # 9.3.3: read firmware version, 40 9C 5F 00
    ("C00011", 0x5FF4, 0),  # 9.2.2: 24575 - 11 (the manual's bytes FF 5F are an erratum)
    ("C00039/1", 0x5FD8, 1),  # 9.2.3
    ("C00002/11", 0x5FFD, 11),
    ("C00350", 0x5EA1, 0),
    ("C00354/4", 0x5E9D, 4),
])
def test_catalog_resolves_the_manuals_examples(registry: ProfileRegistry, profile_id: str, ref: str, index: int,
                                               sub: int) -> None:
    item = Catalog(registry.get(profile_id)).resolve(ref)
    assert (item.index, item.subindex) == (index, sub)


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
def test_every_can_code_sits_at_the_printed_index_with_its_subcodes(registry: ProfileRegistry,
                                                                    profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    for code, index in CAN_CODE_INDEX.items():
        if profile_id == BASELINE and code[1:] not in BASELINE_CODES:
            continue  # C00349 (DIP switches): the BaseLine C parameter list has no such code
        count = CAN_CODE_SUBCODES.get(code)
        subcodes = list(range(1, count + 1)) if count else [0]
        for sub in subcodes:
            item = catalog.resolve(f"{code}/{sub}" if sub else code)
            assert (item.index, item.subindex) == (index, sub), code
    if profile_id == MOTEC:  # 12.1, operating-system parameters of the motec (MCI = communication unit interface)
        assert catalog.resolve("C01501/2").index == 0x5A22
        assert catalog.resolve("C01503/1").index == 0x5A20


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
def test_scaling_reproduces_the_manuals_examples(registry: ProfileRegistry, profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    current = _param(catalog, "C00088")
    assert (current.factor, current.unit) == (100, "A")
    assert to_raw(current, 10.20) == 1020 == 0x3FC
    assert to_raw(current, "10.20 A") == 1020
    assert from_raw(current, 1020).display() == "10.2 A"
    jog = _param(catalog, "C00039/1")
    assert to_raw(jog, 123.45) == 12345 == 0x3039  # data bytes 39 30 00 00
    with pytest.raises(InvalidValue, match="more decimals"):
        to_raw(jog, 123.456)
    heatsink = _param(catalog, "C00061")
    assert (heatsink.data_type, heatsink.factor, heatsink.unit, heatsink.default) == (DataType.INTEGER32, 1, "°C", 43)
    assert from_raw(heatsink, 0x2B).value == 43
    with pytest.raises(ReadOnly):
        to_raw(heatsink, 50)
    firmware = _param(catalog, "C00099")
    assert (firmware.data_type, firmware.default) == (DataType.VISIBLE_STRING, "01.00.00.00")
    assert len(firmware.default) == 11  # the segmented upload announces 0x0B bytes


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
def test_selection_lists_and_limits(registry: ProfileRegistry, profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    baud = _param(catalog, "C00351")
    assert baud.selection == {0: "500 kbit/s", 1: "250 kbit/s", 2: "125 kbit/s", 3: "50 kbit/s",
                              4: "1000 kbit/s", 5: "20 kbit/s", 14: "800 kbit/s"}
    assert from_raw(baud, 14).display() == "14 = 800 kbit/s"
    assert to_raw(baud, "125 kbit/s") == 2
    with pytest.raises(OutOfRange, match="selection list"):
        to_raw(baud, 6)
    assert _param(catalog, "C00352").selection == {0: "Slave", 1: "Master"}
    assert _param(catalog, "C00359").selection[7] == "Reset"
    assert _param(catalog, "C00345").selection[3] == "Bus off"
    assert _param(catalog, "C00347/1").selection[127] == "Pre-operational"
    assert _param(catalog, "C00592/2").selection == {0: "No Reaction", 1: "Fault", 2: "Trouble", 4: "WarningLocked"}
    assert _param(catalog, "C00353/1").selection[2] == "COBID = C0354/x"
    node = _param(catalog, "C00350")
    assert (node.min, node.max, node.default) == (1, 63, 1)
    with pytest.raises(OutOfRange):
        to_raw(node, 64)


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE])
def test_defaults_and_reset_flags(registry: ProfileRegistry, profile_id: str) -> None:
    profile = registry.get(profile_id)
    catalog = Catalog(profile)
    for entry in [*profile.parameters, *profile.objects]:
        if entry.access.readable:
            has_formula = isinstance(entry, ObjectEntry) and entry.default_expr is not None
            assert entry.default is not None or has_formula, entry.name
    resets = {p.ref for p in profile.parameters if p.reset_required}
    assert resets == {"C00350", "C00351", "C00352", "C00354/1", "C00354/2", "C00354/3", "C00354/4"}
    assert [_param(catalog, f"C00354/{n}").default for n in (1, 2, 3, 4)] == [0x201, 0x181, 0x301, 0x281]
    assert [_param(catalog, f"C00357/{n}").default for n in (1, 2)] == [3000, 3000]
    assert _param(catalog, "C00356/1").default == 3000
    assert _param(catalog, "C00353/1").default == 1  # parameter page (ch. 8.3 prints 0 with option 1's text)
    assert _param(catalog, "C00366").default == 0  # only SDO channel 1 in the Lenze setting
    if profile_id == MOTEC:
        assert _param(catalog, "C01501/1").default == 1
        assert _param(catalog, "C01503/1").default == 200
    assert all(p.pdo_mappable for p in profile.parameters if p.code == "C00409")


def test_motec_objects_are_chapter_13(motec: Profile) -> None:
    listed: dict[int, list[int]] = {}
    for obj in motec.objects:
        listed.setdefault(obj.index, []).append(obj.subindex)
    assert listed == MOTEC_OBJECTS
    catalog = Catalog(motec)
    sdo2 = catalog.resolve("0x1201.1").entry
    assert (sdo2.access, sdo2.default) == (Access.RW, 0x80000000)  # SDO2 invalid in the Lenze setting
    assert catalog.resolve("0x1201.0").entry.default == 3  # printed 3; CiA 301 allows 3 for 0x1201 (sub 3 client id)
    assert catalog.resolve("0x1018.1").entry.default == 0x3B
    tpdo1 = catalog.resolve("0x1800.1").entry
    assert isinstance(tpdo1, ObjectEntry) and tpdo1.default_expr == "$NODEID+0x180"
    assert catalog.resolve("0x1401.1").entry.default_expr == "$NODEID+0x300"  # type: ignore[union-attr]
    inhibit = catalog.resolve("0x1800.3").entry
    assert (inhibit.unit, inhibit.factor, from_raw(inhibit, 26).value) == ("ms", 10, 2.6)  # 26 = 2.6 ms
    assert catalog.resolve("0x1006").entry.unit == "µs"
    with pytest.raises(UnknownParameter):
        catalog.resolve("0x1400.4")  # "compatibility entry": every access aborts 0x06090011
    with pytest.raises(UnknownParameter):
        catalog.resolve("0x100C")  # no node guarding objects
    assert (motec.features.sdo_channels, motec.features.rpdo_count, motec.features.tpdo_count) == (2, 2, 2)
    assert motec.features.node_id_range == (1, 63)
    assert motec.features.baud_rates_kbit == [20, 50, 125, 250, 500, 800, 1000]


def test_motec_emergency_codes(motec: Profile) -> None:
    texts = {e.code: e.text for e in motec.emcy_codes}
    assert sorted(texts) == [0x0000, 0x1000, 0x3100, 0x8100, 0x8130, 0x8150, 0x8210, 0x8220, 0x8700, 0xF000]
    assert "heartbeat" in texts[0x8130]
    assert "Collision" in texts[0x8150]
    assert "C00168" in (next(e for e in motec.emcy_codes if e.code == 0xF000).vendor_error or "")


def test_motec_counts(motec: Profile) -> None:
    # 90 + C00866/1...8, C00868/1...8 (CAN input/output words, PDO-mappable) + C00053/C00054 (actual values)
    assert len(motec.parameters) == 108
    assert len({p.code for p in motec.parameters}) == 44
    assert len(motec.objects) == 71
    assert len({o.index for o in motec.objects}) == 19
    assert len(motec.emcy_codes) == 10
    assert motec.identity.vendor_id == 0x3B
    assert motec.identity.device_type == 0


def test_baseline_lists_every_code_of_the_parameter_list(baseline: Profile) -> None:
    codes = list(dict.fromkeys(p.code for p in baseline.parameters))
    assert codes == [f"C{number}" for number in BASELINE_CODES]
    assert len(codes) == 170
    assert len(baseline.parameters) == 216
    assert len(baseline.objects) == 71
    names = {p.code: p.name for p in baseline.parameters}
    assert names["C00324"] == "CAN transmit blocking time"  # the BaseLine C manual's name for C00324
    assert names["C00994"] == "Flying restart fct.: Current"


def test_baseline_shares_the_8400_can_stack(baseline: Profile, motec: Profile) -> None:
    assert [(o.index, o.subindex) for o in baseline.objects] == [(o.index, o.subindex) for o in motec.objects]
    shared = {p.ref for p in motec.parameters if p.code in CAN_CODE_INDEX and p.code != "C00349"}
    assert shared <= {p.ref for p in baseline.parameters}
    assert "C00349" not in {p.code for p in baseline.parameters}


def test_profile_files_are_the_registry_profiles(motec: Profile, baseline: Profile) -> None:
    for profile in (motec, baseline):
        path = Path(settings.profiles_dir) / f"{profile.id}.json"
        assert Profile.model_validate_json(path.read_bytes()) == profile
