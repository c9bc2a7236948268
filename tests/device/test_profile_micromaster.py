"""The Siemens MICROMASTER 420/430/440 CANopen profile against its manual (Operating Instructions, Issue 01/05).

Worked examples are the manual's: r0964.02 -> 0x23C4 sub 2 and P1203.00 -> 0x24B3 sub 0 (ch. 3.2.4), the object
numbers of ch. 5.2 (P0918 0x2396, P2010 0x27DA, P2040 0x27F8, P2041 0x27F9 ...) and the traces of ch. 5.7/5.8.
"""

from __future__ import annotations

from collections import Counter

import pytest

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.addressing import code_to_index, index_to_code
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.profile import Access, ParameterNumberAddressing, Profile
from drivebench.errors import UnknownParameter
from drivebench.protocol.canopen.sdo_server import SdoAbort
from drivebench.protocol.datatypes import DataType
from drivebench.simulator.node import SimulatedNode
from drivebench.simulator.store import ObjectStore

PATH = REPO_ROOT / "device_profiles" / "siemens-micromaster4-canopen.json"


@pytest.fixture(scope="module")
def profile() -> Profile:
    return Profile.model_validate_json(PATH.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def catalog(profile: Profile) -> Catalog:
    return Catalog(profile)


def test_file_validates_with_identity_and_features(profile: Profile) -> None:
    assert profile.id == "siemens-micromaster4-canopen" and profile.family == "siemens-mm4"
    assert isinstance(profile.addressing, ParameterNumberAddressing) and profile.addressing.base == 0x2000
    ident = profile.identity
    assert (ident.vendor_id, ident.product_code, ident.device_type) == (0x06000053, 2, 0x00010192)
    assert ident.order_codes == ["6SE6400-1CB00-0AA0"]
    features = profile.features
    assert features.baud_rates_kbit == [10, 20, 50, 125, 250, 500, 800, 1000]
    assert (features.rpdo_count, features.tpdo_count, features.max_mapping_entries) == (3, 3, 4)
    assert features.node_guarding and features.heartbeat_producer and features.heartbeat_consumers == 0
    assert not features.segmented_sdo and not features.block_sdo and features.sdo_channels == 1
    assert "Issue 01/05" in (profile.source or "")


@pytest.mark.parametrize(("ref", "index", "sub"), [
    ("r0964.2", 0x23C4, 2), ("r0964.02", 0x23C4, 2), ("P1203.00", 0x24B3, 0), ("P1203", 0x24B3, 0),
    ("P2041.2", 0x27F9, 2), ("P2041.0", 0x27F9, 0), ("P2041.4", 0x27F9, 4), ("P0918", 0x2396, 0),
    ("P2010", 0x27DA, 0), ("P2040", 0x27F8, 0), ("P1501", 0x25DD, 0), ("P1503", 0x25DF, 0), ("P0700", 0x22BC, 0),
    ("P1000", 0x23E8, 0), ("P0719", 0x22CF, 0), ("P0927", 0x239F, 0), ("P1300", 0x2514, 0), ("P0014", 0x200E, 0),
    ("P1080", 0x2438, 0), ("P1082", 0x243A, 0), ("P1120", 0x2460, 0), ("P1121", 0x2461, 0), ("P2000", 0x27D0, 0),
    ("P2003", 0x27D3, 0), ("r0947", 0x23B3, 0), ("r2110", 0x283E, 0), ("r2091", 0x282B, 0), ("r2053.4", 0x2805, 4),
    ("r2054.6", 0x2806, 6), ("r2050.2", 0x2802, 3), ("r2050.3", 0x2802, 4), ("r2050.5", 0x2802, 6),
    ("0x6040", 0x6040, 0), ("0x1018.1", 0x1018, 1), ("0x1604sub1", 0x1604, 1),
])
def test_catalog_resolves_the_manuals_addresses(catalog: Catalog, ref: str, index: int, sub: int) -> None:
    item = catalog.resolve(ref)
    assert (item.index, item.subindex) == (index, sub)


def test_parameter_channel_rule_and_free_objects() -> None:
    rule = ParameterNumberAddressing()
    assert [code_to_index(rule, n, s) for n, s in [(2041, 3), (2010, 0), (918, 0), (964, 2), (1203, 0), (1501, 0)]] \
        == [(0x27F9, 3), (0x27DA, 0), (0x2396, 0), (0x23C4, 2), (0x24B3, 0), (0x25DD, 0)]
    assert index_to_code(rule, 0x283E, 0) == (2110, 0)
    for number in (2050, 2051):  # 0x2802/0x2803 are the free process-data objects, not the parameter channel
        with pytest.raises(UnknownParameter):
            code_to_index(rule, number)
    assert index_to_code(rule, 0x2802, 3) is None and index_to_code(rule, 0x2803, 1) is None
    with pytest.raises(UnknownParameter):
        code_to_index(rule, 0x4000)


def test_catalog_names_the_parameter_and_the_object(catalog: Catalog) -> None:
    assert catalog.resolve("P2041.2").name == "CB parameter (PDO properties): PDO5 mapping"
    assert catalog.resolve("r0964.2").ref == "r0964.2"
    assert catalog.resolve("0x1604.1").name == "RPDO5 mapping parameter: 1st mapped object"
    assert catalog.vendor_ref(0x24B3, 0) == "P1203"
    with pytest.raises(UnknownParameter):
        catalog.resolve("P2051.2")


def test_telegram_sizes_of_the_manuals_traces(catalog: Catalog) -> None:
    sizes = {ref: catalog.resolve(ref).entry.data_type for ref in (
        "r0964.2", "P1203", "P2041.0", "P2041.3", "P2040", "P2010", "P0918", "P1501", "0x6060", "0x6061",
        "0x1010.1", "0x1604.1", "0x1400.2", "0x1404.2")}
    assert sizes == {
        "r0964.2": DataType.UNSIGNED16, "P1203": DataType.UNSIGNED16, "P2041.0": DataType.UNSIGNED16,
        "P2041.3": DataType.UNSIGNED16, "P2040": DataType.UNSIGNED16, "P2010": DataType.UNSIGNED16,
        "P0918": DataType.UNSIGNED16, "P1501": DataType.UNSIGNED32, "0x6060": DataType.INTEGER8,
        "0x6061": DataType.INTEGER8, "0x1010.1": DataType.UNSIGNED32, "0x1604.1": DataType.UNSIGNED32,
        "0x1400.2": DataType.UNSIGNED8, "0x1404.2": DataType.UNSIGNED8}


def test_selection_lists_and_bits(catalog: Catalog) -> None:
    assert catalog.resolve("P2010").entry.selection[500] == "500 kbit/s"
    assert sorted(catalog.resolve("P2010").entry.selection) == [10, 20, 50, 125, 250, 500, 800, 1000]
    assert catalog.resolve("0x6060").entry.selection == {2: "Velocity mode", 4: "Profile torque mode"}
    assert catalog.resolve("P0700").entry.selection[6] == "CB on COM link (CANopen)"
    assert catalog.resolve("P1300").entry.selection[22] == "Sensorless vector torque control"
    assert catalog.resolve("r2054.2").entry.selection[4] == "Operational"
    assert catalog.resolve("r2054.0").entry.selection[423] == "CANopen error: Subindex does not exist"
    assert catalog.resolve("r2110").entry.selection[703].startswith("A0703 Node guarding failure")
    assert catalog.resolve("0x1029.1").entry.selection[2] == "Pre-operational with OFF2 (pulses disabled)"
    status = catalog.resolve("0x6041").entry.bits
    assert status[4] == "Voltage disabled (MM: OFF2 active)" and status[10].startswith("Target reached")
    # P2041.02 = 0x2103 (velocity trace): RPDO5 control word + target velocity, TPDO5 status word + actual speed
    mapping = catalog.resolve("P2041.2").entry
    assert [mapping.bits[b] for b in range(16) if 0x2103 >> b & 1] == [
        "RPDO: control word 0x6040", "RPDO: target velocity 0x6042 (or 0x6052, bit 7)", "TPDO: status word 0x6041",
        "TPDO: actual speed 0x6044 (or 0x6054, bit 15) (MM440)"]


def test_defaults_and_access(catalog: Catalog) -> None:
    defaults = {ref: catalog.resolve(ref).entry.default for ref in (
        "P2041.0", "P2041.1", "P2041.2", "P2041.3", "r0964.2", "P0918", "P2010", "0x6060", "0x6061", "0x100C",
        "0x100D", "0x1600.1", "0x1A00.1", "0x604E")}
    assert defaults == {"P2041.0": 0, "P2041.1": 0, "P2041.2": 0, "P2041.3": 0,  # §6.3 "0 = default value on powerup"
                        "r0964.2": 105, "P0918": 3, "P2010": 10, "0x6060": 2, "0x6061": 2, "0x100C": 10,
                        "0x100D": 2, "0x1600.1": 0x60400010, "0x1A00.1": 0x60410010, "0x604E": 1500}
    assert catalog.resolve("P0918").entry.reset_required and catalog.resolve("P2010").entry.reset_required
    assert catalog.resolve("r2054.3").entry.access is Access.RO
    assert catalog.resolve("0x1600.1").entry.access is Access.RO  # PDO1 mapping is fixed
    assert catalog.resolve("0x1604.1").entry.access is Access.RW
    assert catalog.resolve("0x6040").entry.pdo_mappable and catalog.resolve("0x2802.3").entry.pdo_mappable


def test_simulated_drive_holds_the_manuals_cob_ids_and_checks_writes(profile: Profile) -> None:
    store = ObjectStore(profile, 3)
    cob_ids = {index: store.get(index, 1) for index in (0x1400, 0x1404, 0x1405, 0x1800, 0x1804, 0x1805)}
    assert cob_ids == {0x1400: 0x203, 0x1404: 0x303, 0x1405: 0x403, 0x1800: 0x183, 0x1804: 0x283, 0x1805: 0x383}
    assert (store.get(0x1014, 0), store.get(0x1200, 1), store.get(0x1200, 2)) == (0x83, 0x603, 0x583)
    store.write(0x27DA, 0, (500).to_bytes(2, "little"))  # P2010 = 500 kbit/s
    store.write(0x2396, 0, b"\x04")  # P0918 = 4, 1-byte download as traced
    store.write(0x25DD, 0, (0x082B000C).to_bytes(4, "little"))  # P1501 = r2091.12
    store.write(0x6060, 0, b"\x04")
    assert (store.get(0x27DA, 0), store.get(0x2396, 0), store.get(0x6060, 0)) == (500, 4, 4)
    refused = []
    for index, sub, data in [(0x27DA, 0, (501).to_bytes(2, "little")), (0x6060, 0, b"\x03"),
                             (0x24B3, 0, (5).to_bytes(2, "little")), (0x23C4, 2, b"\x01\x00"),
                             (0x1600, 1, (0x60420010).to_bytes(4, "little")), (0x2801, 0, b"\x00\x00")]:
        with pytest.raises(SdoAbort) as caught:
            store.write(index, sub, data)
        refused.append(caught.value.code)
    assert refused == [0x06090030, 0x06090030, 0x06090030, 0x06010002, 0x06010002, 0x06020000]


def test_emcy_codes(profile: Profile) -> None:
    first = {}
    for entry in profile.emcy_codes:
        first.setdefault(entry.code, entry)
    assert first[0x7001].vendor_error == "F0070" and "setpoint timeout" in first[0x7001].text
    assert first[0x8110].vendor_error is None and first[0x8110].text.startswith("CAN overrun")
    assert first[0x2310].vendor_error == "F0001" and first[0x7332].vendor_error == "F0030"
    assert first[0x7137].vendor_error == "F0041"
    alarms = sorted(e.vendor_error for e in profile.emcy_codes if (e.vendor_error or "").startswith("A"))
    assert alarms == ["A0701", "A0702", "A0703", "A0704", "A0707"]
    faults = {e.vendor_error for e in profile.emcy_codes if (e.vendor_error or "").startswith("F")}
    assert len(faults) == 32


def test_counts(profile: Profile) -> None:
    """What was extracted from the manual; an edit that drops entries fails here."""
    assert len(profile.objects) == 112
    assert len({o.index for o in profile.objects}) == 52
    # + r0026, r0027, r0031, r0037 (actual values, MM440 parameter list); + P0010, P0100, P0300, P0304, P0305, P0307,
    # P0308, P0309, P0310, P0311, P3900 (quick commissioning, issue 30)
    assert len(profile.parameters) == 85
    assert len({p.code for p in profile.parameters}) == 65
    assert len(profile.emcy_codes) == 63
    groups = Counter(p.group for p in profile.parameters) + Counter(o.group for o in profile.objects)
    assert set(groups) == set(profile.groups)
    assert all(entry.default is not None or entry.default_expr is not None
               for entry in profile.objects if entry.access.readable)
    # a default no read source gives stays empty, and the entry's source says so
    assert all(par.default is not None or "not read" in (par.source or "") for par in profile.parameters)


def test_mapping_changes_on_a_valid_pdo_as_the_manual_does(profile: Profile) -> None:
    """Ch. 5.4: sub 0 := 0, entries in ascending order, sub 0 := count - without invalidating the COB-ID first."""
    assert profile.features.mapping_needs_invalid_pdo is False
    node = SimulatedNode(profile, 3, send=lambda cob_id, data: None)
    store = node.store
    assert store.get(0x1404, 1) == 0x303  # RPDO5 valid
    # the manual's RPDO5 example: control word, free object 0x2802.3, target torque, modes of operation
    example = [(1, 0x60400010, 4), (2, 0x28020310, 4), (3, 0x60710010, 4), (4, 0x60600008, 4), (0, 4, 1)]
    for sub, value, size in example:
        store.write(0x1604, sub, value.to_bytes(size, "little"))
    assert [store.get(0x1604, sub) for sub in range(5)] == [4, 0x60400010, 0x28020310, 0x60710010, 0x60600008]
    with pytest.raises(SdoAbort) as caught:  # entries change only while sub 0 is 0
        store.write(0x1604, 3, (0x60420010).to_bytes(4, "little"))
    assert caught.value.code == 0x06040043
