"""COB-IDs per family: 8400 motec §7.1.1 base-ID table, EMF2178IB §8.1 and its worked SDO identifiers."""

from __future__ import annotations

import pytest

from drivebench.config import settings
from drivebench.device.calculators.cobids import alternative_hint, channels_of, cob_ids, default_channels
from drivebench.device.calculators.switches import SwitchesSection
from drivebench.device.profiles.loader import load_profile_file
from drivebench.errors import InvalidValue, OutOfRange
from tests.conftest import shipped_switch_devices

DEVICES = shipped_switch_devices()
LENZE_8400_MOTEC = DEVICES.get("lenze-8400-motec").spec
LENZE_EMF2178IB = DEVICES.get("lenze-emf2178ib").spec
SIEMENS_MM4 = DEVICES.get("siemens-mm4").spec


def table(spec: SwitchesSection, node: int, **kw: object) -> dict[str, int]:
    return {c.service: c.cob_id for c in cob_ids(spec, node, **kw)}  # type: ignore[arg-type]


# 8400 motec §7.1.1: (service, Lenze base, CANopen base)
BASE_8400 = [
    ("NMT", 0, 0),
    ("SYNC", 128, 128),
    ("EMCY", 128, 128),
    ("TPDO1", 384, 384),
    ("RPDO1", 512, 512),
    ("TPDO2", 640, 640),
    ("RPDO2", 641, 768),
    ("SDO1 tx", 1408, 1408),
    ("SDO1 rx", 1536, 1536),
    ("SDO2 tx", 1472, 1472),
    ("SDO2 rx", 1600, 1600),
    ("Heartbeat / boot-up", 1792, 1792),
]


@pytest.mark.parametrize(("service", "lenze", "canopen"), BASE_8400)
def test_8400_base_id_table_rows(service: str, lenze: int, canopen: int) -> None:
    node = 9
    offset = 0 if service in ("NMT", "SYNC") else node
    assert table(LENZE_8400_MOTEC, node, pdo_ids="lenze")[service] == lenze + offset
    assert table(LENZE_8400_MOTEC, node)[service] == canopen + offset


def test_8400_lenze_rpdo2_equals_tpdo2_of_next_node() -> None:
    assert (
        table(LENZE_8400_MOTEC, 4, pdo_ids="lenze")["RPDO2"] == table(LENZE_8400_MOTEC, 5)["TPDO2"] == 0x285
    )
    assert alternative_hint(LENZE_8400_MOTEC, 4, 0x285) == "Lenze base ID of RPDO2"  # the PDO tab's hint
    assert alternative_hint(LENZE_8400_MOTEC, 4, 0x305) is None
    assert alternative_hint(LENZE_EMF2178IB, 4, 0x285) is None


def test_emf_manual_sdo_identifiers_and_derived_node_5_set() -> None:
    ids = table(LENZE_EMF2178IB, 5)
    assert (ids["SDO1 rx"], ids["SDO1 tx"]) == (1541, 1413)  # §8.1: 1536 + 5, 1408 + 5
    assert table(LENZE_EMF2178IB, 1)["SDO1 rx"] == 1537
    assert ids == {
        "NMT": 0x000,
        "SYNC": 0x080,
        "EMCY": 0x085,
        "TPDO1": 0x185,
        "RPDO1": 0x205,
        "TPDO2": 0x285,
        "RPDO2": 0x305,
        "TPDO3": 0x385,
        "RPDO3": 0x405,
        "SDO1 tx": 0x585,
        "SDO1 rx": 0x605,
        "SDO2 tx": 0x5C5,
        "SDO2 rx": 0x645,
        "Heartbeat / guarding / boot-up": 0x705,
    }


def test_emf_sdo2_is_sdo1_of_address_plus_64() -> None:
    for node in (1, 23, 63):
        assert table(LENZE_EMF2178IB, node)["SDO2 rx"] == table(LENZE_EMF2178IB, node + 64)["SDO1 rx"]
        assert table(LENZE_EMF2178IB, node)["SDO2 tx"] == table(LENZE_EMF2178IB, node + 64)["SDO1 tx"]


def test_mm4_pdo_1_5_6() -> None:
    ids = table(SIEMENS_MM4, 3)
    assert (ids["SDO1 rx"], ids["SDO1 tx"]) == (0x603, 0x583)  # the manual's telegram example
    assert (ids["RPDO5"], ids["TPDO5"], ids["RPDO6"], ids["TPDO6"]) == (0x303, 0x283, 0x403, 0x383)
    assert "sdo2" not in channels_of(SIEMENS_MM4)


def test_hex_decimal_and_channel_filter() -> None:
    rows = cob_ids(LENZE_8400_MOTEC, 63, channels={"pdo1"})
    services = [r.service for r in rows]
    assert "TPDO2" not in services and "SDO2 rx" not in services and "TPDO1" in services
    emcy = next(r for r in rows if r.service == "EMCY")
    assert (emcy.hex, emcy.cob_id) == ("0x0BF", 191)
    assert emcy.model_dump()["hex"] == "0x0BF"
    assert default_channels(LENZE_8400_MOTEC) == {"sdo1", "pdo1", "pdo2"}


def test_rejects_out_of_range_and_lenze_ids_elsewhere() -> None:
    with pytest.raises(OutOfRange):
        cob_ids(LENZE_8400_MOTEC, 64)
    with pytest.raises(InvalidValue):
        cob_ids(SIEMENS_MM4, 3, pdo_ids="lenze")
    assert cob_ids(LENZE_EMF2178IB, 127)[-1].cob_id == 0x77F


@pytest.mark.parametrize("profile_file", ["lenze-8200-vector-emf2178ib.json", "lenze-93xx-emf2178ib.json"])
def test_emf_pdo_channels_on_by_default_like_the_profiles(profile_file: str) -> None:
    """§8.1 lists PDO2/PDO3 like PDO1 (only SDO2 is "Lenze setting: not active"); the profiles hold them valid
    (I-1401/I-1402/I-1801/I-1802 sub 1 bit 31 clear, C1865/3 and /4 = 1). The table must say the same."""
    profile = load_profile_file((settings.profiles_dir / profile_file).read_bytes(), profile_file)
    cob_id_defaults = {(o.index, o.subindex): o.default_expr for o in profile.objects}
    validity = {p.subcode: p.default for p in profile.parameters if p.code == "C1865"}
    on = default_channels(LENZE_EMF2178IB)
    rpdo_base, tpdo_base = {1: 0x200, 2: 0x300, 3: 0x400}, {1: 0x180, 2: 0x280, 3: 0x380}
    for number in (1, 2, 3):
        assert cob_id_defaults[(0x1400 + number - 1, 1)] == f"$NODEID+0x{rpdo_base[number]:X}"  # bit 31 clear
        assert cob_id_defaults[(0x1800 + number - 1, 1)] == f"$NODEID+0x{tpdo_base[number]:X}"
        assert validity[number + 1] == 1
        assert f"pdo{number}" in on
    assert "sdo2" not in on and validity[1] == 0
