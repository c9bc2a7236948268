"""The shipped EMF2178IB profiles (8200 vector, 93XX) against the communication manual (seed 001, EDSMF2178IB
EN 3.0; the seed text ends after object I-100C): code -> index with parameter sets (10.1, 10.2), the worked
telegram examples (10.5), FIX32 scaling and its exceptions (10.3), the C18xx code family (7, 10.6.2)."""

from __future__ import annotations

import pytest

from drivebench.config import settings
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Access, ObjectEntry, Parameter, Profile
from drivebench.device.profiles.scaling import from_raw, to_raw
from drivebench.errors import OutOfRange, ReadOnly, UnknownParameter
from drivebench.protocol.datatypes import DataType

VECTOR = "lenze-8200-vector-emf2178ib"
SERVO = "lenze-93xx-emf2178ib"
BOTH = [VECTOR, SERVO]

# Module codes (C18xx family) and their indices (printed where the manual prints them, else 24575 - code).
MODULE_CODES = {
    "C1500": 0x5A23, "C1822/1": 0x58E1, "C1823/1": 0x58E0, "C1824/2": 0x58DF, "C1825/9": 0x58DE, "C1827": 0x58DC,
    "C1828": 0x58DB, "C1850": 0x58C5, "C1851": 0x58C4, "C1852": 0x58C3, "C1853/3": 0x58C2, "C1855/6": 0x58C0,
    "C1856/1": 0x58BF, "C1857/1": 0x58BE, "C1865/1": 0x58B6, "C1867": 0x58B4, "C1868": 0x58B3, "C1869": 0x58B2,
    "C1870/2": 0x58B1, "C1871": 0x58B0, "C1872": 0x58AF, "C1873/1": 0x58AE, "C1874/1": 0x58AD, "C1875/1": 0x58AC,
    "C1882/5": 0x58A5,
}
# 13.2 overview: every object the module implements, with the subindices the profile serves.
OBJECTS = {
    0x1000: [0], 0x1001: [0], 0x1003: list(range(11)), 0x1005: [0], 0x1006: [0], 0x1008: [0], 0x100A: [0],
    0x100C: [0], 0x100D: [0], 0x1010: [0, 1, 2, 3], 0x1011: list(range(8)), 0x1014: [0], 0x1015: [0],
    0x1016: [0, 1], 0x1017: [0], 0x1018: [0, 1, 2, 3, 4], 0x1029: [0, 1], 0x1200: [0, 1, 2], 0x1201: [0, 1, 2, 3],
    **{index: [0, 1, 2, 5] for index in (0x1400, 0x1401, 0x1402)},
    **{index: [0, 1, 2, 3, 4] for index in (0x1600, 0x1601, 0x1602, 0x1A00, 0x1A01, 0x1A02)},
    **{index: [0, 1, 2, 3, 5] for index in (0x1800, 0x1801, 0x1802)},
}


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory) -> ProfileRegistry:
    return ProfileRegistry(settings.profiles_dir, tmp_path_factory.mktemp("no-uploads"))


@pytest.fixture(scope="module")
def vector(registry: ProfileRegistry) -> Catalog:
    return Catalog(registry.get(VECTOR))


@pytest.fixture(scope="module")
def servo(registry: ProfileRegistry) -> Catalog:
    return Catalog(registry.get(SERVO))


def _param(catalog: Catalog, ref: str) -> Parameter:
    entry = catalog.resolve(ref).entry
    assert isinstance(entry, Parameter)
    return entry


def _address(catalog: Catalog, ref: str) -> tuple[int, int]:
    item = catalog.resolve(ref)
    return item.index, item.subindex


@pytest.mark.parametrize("profile_id", BOTH)
def test_profile_file_validates_and_loads_without_errors(registry: ProfileRegistry, profile_id: str) -> None:
    path = settings.profiles_dir / f"{profile_id}.json"
    assert Profile.model_validate_json(path.read_text(encoding="utf-8")) == registry.get(profile_id)
    assert path.name not in {name for name, _ in registry.errors}
    profile = registry.get(profile_id)
    assert profile.family == "lenze-emf2178ib"
    assert profile.identity.vendor_id == 0x3B
    assert profile.features.baud_rates_kbit == [10, 20, 50, 125, 250, 500, 1000]
    assert (profile.features.sdo_channels, profile.features.node_guarding) == (2, True)


@pytest.mark.parametrize("profile_id", BOTH)
def test_the_manuals_telegram_examples_resolve(registry: ProfileRegistry, profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    assert _address(catalog, "C0061") == (0x5FC2, 0)  # read heatsink temperature, 40 C2 5F 00
    assert _address(catalog, "C61") == (0x5FC2, 0)
    assert _address(catalog, "C0012") == (0x5FF3, 0)  # write acceleration time, 23 F3 5F 00
    assert _address(catalog, "C0200") == (0x5F37, 0)  # block read of the software product code, 40 37 5F 00
    assert _address(catalog, "C0009") == (0x5FF6, 0)
    assert _address(catalog, "C0358") == (0x5E99, 0)
    for ref, index in MODULE_CODES.items():
        assert _address(catalog, ref)[0] == index, ref
    assert _address(catalog, "C1870/1") == (0x58B1, 1)  # consumer heartbeat time; /2 producer


@pytest.mark.parametrize("profile_id", BOTH)
def test_fix32_scaling_and_the_raw_exceptions(registry: ProfileRegistry, profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    heatsink = _param(catalog, "C0061")
    assert (heatsink.data_type, heatsink.factor, heatsink.unit) == (DataType.INTEGER32, 10000, "°C")
    assert from_raw(heatsink, 0x00068FB0).value == 43  # response data B0 8F 06 00
    assert heatsink.default == 43
    with pytest.raises(ReadOnly):
        to_raw(heatsink, 40)
    assert to_raw(_param(catalog, "C0012"), 20) == 200000 == 0x00030D40  # data bytes 40 0D 03 00
    assert to_raw(_param(catalog, "C0012"), "20 s") == 200000
    assert from_raw(_param(catalog, "C1870/2"), 1000000).value == 100
    guard = _param(catalog, "C1827")
    assert (guard.factor, guard.unit, guard.min, guard.max, guard.default) == (10000, "ms", 0, 65535, 0)
    assert to_raw(_param(catalog, "C1828"), 255) == 2550000
    with pytest.raises(OutOfRange):
        to_raw(_param(catalog, "C1828"), 256)
    code = _param(catalog, "C0200")
    assert code.data_type is DataType.VISIBLE_STRING and len(code.default) == 14  # type: ignore[arg-type]
    assert _param(catalog, "C1500").data_type is DataType.VISIBLE_STRING
    fix32 = [p for p in catalog.profile.parameters if p.data_type is DataType.INTEGER32 and p.factor == 10000]
    assert len(fix32) > 40


def test_8200_parameter_sets(vector: Catalog) -> None:
    # 10.2.1: code + 2000 per parameter set; C0011 in sets 1...4 = 11, 2011, 4011, 6011
    assert [_address(vector, ref) for ref in ("C0011", "C2011", "C4011", "C6011")] == [
        (0x5FF4, 0), (0x5824, 0), (0x5054, 0), (0x4884, 0)]
    second = vector.resolve("C2012")
    assert (second.index, second.parameter_set) == (0x5823, 2)  # index bytes 23 58
    assert vector.resolve("C6001").parameter_set == 4  # C0001 must be equal in all parameter sets
    assert vector.profile.addressing.set_offset == 2000  # type: ignore[union-attr]
    with pytest.raises(UnknownParameter):
        vector.resolve("C2061")  # the heatsink temperature exists once
    with pytest.raises(UnknownParameter):
        vector.resolve("C8011")  # no fifth parameter set


def test_8200_control_and_status_word_have_no_factor(vector: Catalog) -> None:
    control, status = _param(vector, "C0135"), _param(vector, "C0150")
    assert (control.factor, status.factor) == (1, 1)  # 10.3: C0135 and C0150 are bit code without factor
    assert _address(vector, "C0135") == (0x5F78, 0)
    assert _address(vector, "C0150") == (0x5F69, 0)
    assert to_raw(control, 0x047F) == 0x047F
    assert len(control.bits) == len(status.bits) == 16
    assert to_raw(_param(vector, "C0001"), 3) == 30000  # C0001 = 3: process data via AIF
    # Fig. 9-4: C0421/1 and /2 select what AIF-OUT.W1/W2 carry; FIX32 like every code but C0135/C0150
    assert [_address(vector, f"C0421/{n}") for n in (1, 2)] == [(0x5E5A, 1), (0x5E5A, 2)]
    assert _param(vector, "C0421/2").factor == 10000


def test_93xx_parameter_sets_are_not_bus_addressable(servo: Catalog) -> None:
    # 10.2.2: only the current parameter set can be addressed via the bus (the "sets 1...4" is 8200 only)
    assert servo.profile.addressing.set_offset == 0  # type: ignore[union-attr]
    assert all(p.parameter_sets == 1 for p in servo.profile.parameters)
    with pytest.raises(UnknownParameter):
        servo.resolve("C2012")
    assert _address(servo, "C0005") == (0x5FFA, 0)
    assert to_raw(_param(servo, "C0005"), 1013) == 10130000  # = 0x009A9250
    assert _address(servo, "C0142") == (0x5F71, 0)


@pytest.mark.parametrize("profile_id", BOTH)
def test_c18xx_family_not_c23xx(registry: ProfileRegistry, profile_id: str) -> None:
    codes = {p.code for p in registry.get(profile_id).parameters}
    assert {"C1850", "C1851", "C1865", "C1870"} <= codes
    assert not any(code.startswith("C23") for code in codes)
    assert not {"C2120", "C2121", "C7998", "C7999"} & codes  # Servo PLC / Drive PLC / ECS only
    catalog = Catalog(registry.get(profile_id))
    with pytest.raises(UnknownParameter):
        catalog.resolve("C2350")  # on these base devices never the module's node address


@pytest.mark.parametrize("profile_id", BOTH)
def test_selection_lists(registry: ProfileRegistry, profile_id: str) -> None:
    catalog = Catalog(registry.get(profile_id))
    sdo2 = _param(catalog, "C1865/1")
    assert sdo2.selection == {0: "Deactivated (Lenze setting)", 10000: "Activated"}  # raw FIX32 values
    assert to_raw(sdo2, 1) == 10000
    assert to_raw(sdo2, "Activated") == 10000
    assert from_raw(sdo2, 10000).display() == "10000 = Activated"
    assert sdo2.default == 0 and sdo2.reset_required
    behaviour = catalog.resolve("0x1029.1").entry
    assert behaviour.selection == {0: "Change to Pre-operational", 1: "No state change", 2: "Change to Stopped"}
    assert all(p.reset_required for p in catalog.profile.parameters if p.code in ("C1850", "C1851"))


def test_8200_identity_strings_are_the_manuals_examples(vector: Catalog) -> None:
    assert _param(vector, "C0200").default == "82S8212V_14000"  # 10.5 block read: 82S8212 + V_14000
    assert vector.resolve("0x1008").entry.default == "8212_AFU0"
    assert vector.resolve("0x100A").entry.default == "14000_20000"


def test_8200_parameter_saving(vector: Catalog) -> None:
    saving = _param(vector, "C0003")
    assert saving.selection[10000] == "Automatic saving (Lenze setting)"
    assert from_raw(saving, to_raw(saving, saving.default)).text == "Automatic saving (Lenze setting)"
    assert to_raw(saving, 0) == 0


@pytest.mark.parametrize("profile_id", BOTH)
def test_objects(registry: ProfileRegistry, profile_id: str) -> None:
    profile = registry.get(profile_id)
    listed: dict[int, list[int]] = {}
    for obj in profile.objects:
        listed.setdefault(obj.index, []).append(obj.subindex)
    assert listed == OBJECTS
    catalog = Catalog(profile)
    # 13.2.6/13.2.7: characters 4-7 (10-14) of the base device's C0200, "_", the same characters of C1500
    base, module = str(_param(catalog, "C0200").default), str(_param(catalog, "C1500").default)
    name, version = catalog.resolve("0x1008").entry, catalog.resolve("0x100A").entry
    assert (name.access, name.data_type, name.default) == (
        Access.CONST, DataType.VISIBLE_STRING, f"{base[3:7]}_{module[3:7]}")
    assert (version.access, version.default) == (Access.CONST, f"{base[9:14]}_{module[9:14]}")
    assert len(name.default) == 9 and len(version.default) == 11  # type: ignore[arg-type]
    guard = catalog.resolve("0x100C").entry
    assert (guard.data_type, guard.access, guard.default, guard.unit) == (DataType.UNSIGNED16, Access.RW, 0, "ms")
    assert catalog.resolve("0x1005").entry.default == 0x80
    assert catalog.resolve("0x1006").entry.unit == "µs"  # CiA 301 wins over the printed "ms"
    sdo2 = catalog.resolve("0x1201.1").entry
    assert isinstance(sdo2, ObjectEntry) and sdo2.default_expr == "$NODEID+0x80000640"  # address + 64, invalid
    for entry in [*profile.parameters, *profile.objects]:
        if entry.access.readable:
            has_formula = isinstance(entry, ObjectEntry) and entry.default_expr is not None
            assert entry.default is not None or has_formula, entry.name


@pytest.mark.parametrize("profile_id", BOTH)
def test_emergency_codes_and_notes(registry: ProfileRegistry, profile_id: str) -> None:
    profile = registry.get(profile_id)
    texts = {e.code: e.text for e in profile.emcy_codes}
    assert sorted(texts) == [0x0000, 0x1000, 0x3100, 0x6280, 0x8100, 0x8130, 0x8210, 0x8220, 0x8700]
    assert "heartbeat" in texts[0x8130]
    notes = " ".join(profile.notes)
    assert "after object I-100C" in notes and "missing" in notes and "unknown" in notes
    assert "CiA 301 wins" in notes


# 8200 vector: + C0053 / C0054 (actual values from the 8200 code table)
@pytest.mark.parametrize(("profile_id", "parameters", "codes"), [(VECTOR, 161, 47), (SERVO, 181, 50)])
def test_counts(registry: ProfileRegistry, profile_id: str, parameters: int, codes: int) -> None:
    profile = registry.get(profile_id)
    assert len(profile.parameters) == parameters
    assert len({p.code for p in profile.parameters}) == codes
    assert len(profile.objects) == 107
    assert len(profile.emcy_codes) == 9
