"""The shipped Lenze 8400 motec EtherCAT profile against its manual (seed 004: communication manual 8400 motec
EtherCAT, E84DGFCTxxx: chapters 9.2 to 9.4, 12 and 13)."""

from __future__ import annotations

import pytest

from drivebench.config import settings
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Access, Parameter, Profile
from drivebench.device.profiles.scaling import from_raw, to_raw
from drivebench.errors import OutOfRange, ReadOnly
from drivebench.protocol.datatypes import DataType

ETHERCAT = "lenze-8400-motec-ethercat"

# 13.3 table of attributes and 9.4: code -> (index, data type, writable).
CODE_TABLE = {
    "C13850": (0x29E5, DataType.UNSIGNED16, False), "C13851": (0x29E4, DataType.UNSIGNED16, False),
    "C13859": (0x29DC, DataType.UNSIGNED16, False), "C13860": (0x29DB, DataType.UNSIGNED16, False),
    "C13861": (0x29DA, DataType.UNSIGNED16, False), "C13864": (0x29D7, DataType.UNSIGNED16, False),
    "C13867": (0x29D4, DataType.OCTET_STRING, False), "C13879": (0x29C8, DataType.UNSIGNED16, False),
    "C13880": (0x29C7, DataType.UNSIGNED8, True), "C13881": (0x29C6, DataType.UNSIGNED16, True),
    "C13885": (0x29C2, DataType.UNSIGNED8, True), "C13899": (0x29B4, DataType.UNSIGNED16, True),
    "C13900": (0x29B3, DataType.VISIBLE_STRING, False), "C13901": (0x29B2, DataType.VISIBLE_STRING, False),
    "C13902": (0x29B1, DataType.VISIBLE_STRING, False),
}
SUBCODES = {"C13850": range(1, 11), "C13851": range(1, 9), "C13880": range(1, 2)}
# 9.3: the implemented CoE objects and their subindices.
COE_OBJECTS = {
    0x1000: [0], 0x1001: [0], 0x1008: [0], 0x1009: [0], 0x100A: [0], 0x1018: [0, 1, 2, 3, 4],
    0x1600: list(range(9)), 0x1A00: list(range(11)), 0x1C00: [0, 1], 0x1C10: [0], 0x1C11: [0], 0x1C12: [0, 1],
    0x1C13: [0, 1], 0x1C32: list(range(7)), 0x1C33: list(range(7)),
}


@pytest.fixture(scope="module")
def profile(tmp_path_factory: pytest.TempPathFactory) -> Profile:
    registry = ProfileRegistry(settings.profiles_dir, tmp_path_factory.mktemp("no-uploads"))
    assert f"{ETHERCAT}.json" not in {name for name, _ in registry.errors}
    return registry.get(ETHERCAT)


@pytest.fixture(scope="module")
def catalog(profile: Profile) -> Catalog:
    return Catalog(profile)


def _param(catalog: Catalog, ref: str) -> Parameter:
    entry = catalog.resolve(ref).entry
    assert isinstance(entry, Parameter)
    return entry


def test_file_validates(profile: Profile) -> None:
    path = settings.profiles_dir / f"{ETHERCAT}.json"
    assert Profile.model_validate_json(path.read_text(encoding="utf-8")) == profile
    assert profile.features.transport == "ethercat_coe"
    assert (profile.identity.vendor_id, profile.identity.product_code) == (0x3B, 841020)


def test_every_code_at_its_printed_index(catalog: Catalog) -> None:
    for code, (index, data_type, writable) in CODE_TABLE.items():
        for sub in SUBCODES.get(code, [0]):
            item = catalog.resolve(f"{code}/{sub}" if sub else code)
            assert (item.index, item.subindex) == (index, sub), code
            assert item.entry.data_type is data_type, code
            assert item.entry.access.writable is writable, code
    # 9.2: C00002 -> 24575 - 2 = 24573 = 0x5FFD; C00002/11 = 1 saves all parameter sets
    assert (catalog.resolve("C00002/11").index, catalog.resolve("C00002/11").subindex) == (0x5FFD, 11)
    assert catalog.resolve("C00007").index == 0x5FF8
    assert catalog.resolve("C01501/2").index == 0x5A22
    assert catalog.resolve("C01503/1").index == 0x5A20


def test_upload_and_mapping_examples(catalog: Catalog) -> None:
    # 9.2 upload example: index 0x5FD8 sub 1, standard value of C00039/1 = 0x0FA0
    setpoint = catalog.resolve("C00039/1")
    assert (setpoint.index, setpoint.subindex) == (0x5FD8, 1)
    assert isinstance(setpoint.entry, Parameter) and to_raw(setpoint.entry, setpoint.entry.default) == 0x0FA0
    # 9.2 download example: 0x5C930110 into I-1600.1 maps index 0x5C93 sub 1, 16 bits = C00876/1
    mapping = catalog.resolve("0x1600.1")
    assert (mapping.entry.access, mapping.entry.data_type) == (Access.RW, DataType.UNSIGNED32)
    mapped = catalog.by_address(0x5C930110 >> 16, (0x5C930110 >> 8) & 0xFF)
    assert mapped is not None and mapped.ref == "C00876/1"
    assert mapped.entry.pdo_mappable and (mapped.entry.data_type.size or 0) * 8 == 0x10


def test_selection_lists_ranges_and_defaults(catalog: Catalog) -> None:
    reaction = _param(catalog, "C13880/1")
    assert reaction.selection == {0: "No response", 1: "Error", 4: "Warning locked"}
    assert reaction.default == 0
    assert from_raw(reaction, 4).display() == "4 = Warning locked"
    assert _param(catalog, "C01501/1").selection == {0: "No response", 1: "Error", 4: "Warning locked"}
    assert [_param(catalog, f"C01501/{n}").default for n in (1, 2)] == [1, 1]
    clear = _param(catalog, "C13885")
    assert (clear.min, clear.max, clear.default) == (0, 1, 1)
    monitor = _param(catalog, "C13881")
    assert (monitor.unit, monitor.default, monitor.max) == ("ms", 0, 65535)
    alias = _param(catalog, "C13899")
    assert (alias.min, alias.max, alias.default) == (0, 32767, 0)
    with pytest.raises(OutOfRange):
        to_raw(alias, 32768)
    assert (_param(catalog, "C13859").max, _param(catalog, "C13860").max) == (10, 8)
    assert _param(catalog, "C13879").bits[0] == "General bus error"
    assert _param(catalog, "C13900").default == "E84DFFET"
    assert _param(catalog, "C13901").default == "Mar 21 2005 12:31:21"
    assert _param(catalog, "C13902").default == "01.00.00.00"
    with pytest.raises(ReadOnly):
        to_raw(_param(catalog, "C13864"), 1)
    assert not any(p.pdo_mappable for p in catalog.profile.parameters if p.code.startswith("C13"))


def test_coe_objects(profile: Profile, catalog: Catalog) -> None:
    listed: dict[int, list[int]] = {}
    for obj in profile.objects:
        listed.setdefault(obj.index, []).append(obj.subindex)
    assert listed == COE_OBJECTS
    assert catalog.resolve("0x1018.2").entry.default == 841020
    assert catalog.resolve("0x1600.0").entry.max == 8
    assert catalog.resolve("0x1A00.0").entry.max == 10
    assert all(not o.access.writable for o in profile.objects if o.index >= 0x1C00)  # no PDO assignment switching
    for entry in [*profile.parameters, *profile.objects]:
        if entry.access.readable:
            assert entry.default is not None, entry.name


def test_error_messages(profile: Profile) -> None:
    by_code = {e.code: e for e in profile.emcy_codes}
    assert "bytes 5...8" in by_code[0x1000].text
    assert by_code[0x01BC8131].text.startswith('"Operational" status quit')
    assert "C13880/1" in (by_code[0x01BC8131].vendor_error or "")
    assert "C00002/11" in (by_code[0x01BC6430].remedy or "")


def test_counts(profile: Profile) -> None:
    assert len(profile.parameters) == 39  # C00876/2 (MCI_IN word 2, the control section's setpoint) next to C00876/1
    assert len({p.code for p in profile.parameters}) == 21
    assert len(profile.objects) == 52
    assert len(profile.emcy_codes) == 13


def test_notes_and_exported_eds_say_the_unit_is_reached_through_a_master(profile: Profile) -> None:
    """Issue 33: the notes (and the EDS exported from them) still said DriveBench cannot reach the unit, though
    sessions reach it through a master's mailbox gateway or DriveBench's own master."""
    eds = export_eds(profile)
    text = eds.decode("latin-1") if isinstance(eds, bytes) else str(eds)
    for said in (" ".join(profile.notes), text):
        assert "cannot reach" not in said and "Offline editing only" not in said
        assert "ethercat-mbg:" in said and "ethercat:" in said
