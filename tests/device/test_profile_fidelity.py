"""Profile values checked against the manuals' lines (issue 20, items 1 to 7), each with the line it follows."""

from __future__ import annotations

import re

import pytest

from drivebench.device.profiles.addressing import code_to_index, index_to_code
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Access, CodeAddressing, Profile
from drivebench.errors import UnknownParameter
from drivebench.protocol.datatypes import DataType

MOTEC, BASELINE = "lenze-8400-motec-canopen", "lenze-8400-baseline-c"
VECTOR, SERVO = "lenze-8200-vector-emf2178ib", "lenze-93xx-emf2178ib"
MM4, ETHERCAT = "siemens-micromaster4-canopen", "lenze-8400-motec-ethercat"


def catalog(registry: ProfileRegistry, profile_id: str) -> Catalog:
    return Catalog(registry.get(profile_id))


def default(registry: ProfileRegistry, profile_id: str, ref: str) -> object:
    return catalog(registry, profile_id).resolve(ref).entry.default


@pytest.mark.parametrize("profile_id", [MOTEC, BASELINE, VECTOR, SERVO])
def test_sdo2_server_sub_0_is_3_with_the_client_node_id(registry: ProfileRegistry, profile_id: str) -> None:
    """8400 motec §13 I-1201 'Highest subindex supported | 3 | ro | U8' (EMF2178IB p. 107 the same); CiA 301 allows
    3 for 0x1201 ... 0x127F, sub 3 = node ID of the SDO client."""
    items = catalog(registry, profile_id)
    assert items.resolve("0x1201.0").entry.default == 3
    client = items.resolve("0x1201.3").entry
    assert (client.data_type, client.access) == (DataType.UNSIGNED8, Access.RW)


@pytest.mark.parametrize("profile_id", [VECTOR, SERVO])
def test_sdo1_server_sub_0_stays_2_as_cia_301_fixes_it(registry: ProfileRegistry, profile_id: str) -> None:
    """EMF2178IB p. 107 prints 3 for I-1200 too, but CiA 301 gives the default server SDO 0x1200 only sub 1 and 2."""
    assert default(registry, profile_id, "0x1200.0") == 2
    assert "CiA 301 fixes 0x1200" in (catalog(registry, profile_id).resolve("0x1200.0").entry.description or "")


def test_mm4_p2041_defaults_are_0(registry: ProfileRegistry) -> None:
    """§6.3.1/6.3.2: P2041.1 and P2041.3 '0 = default value on powerup'; §5.4 PDO5/6 'Default: No mapping'. The
    mapping objects 0x1604/0x1A04 (PDO5) then agree with P2041.02 = 0, and the TPDO1/5 types with P2041.00 = 0."""
    assert [default(registry, MM4, f"P2041.{sub}") for sub in range(4)] == [0, 0, 0, 0]
    assert default(registry, MM4, "0x1604") == default(registry, MM4, "0x1A04") == 0
    assert default(registry, MM4, "0x1800.2") == default(registry, MM4, "0x1804.2") == 0


def test_mm4_p0918_is_u16_rw(registry: ProfileRegistry) -> None:
    """Object table: P0918 (0x2396) node ID, U16 rw."""
    entry = catalog(registry, MM4).resolve("P0918").entry
    assert (entry.data_type, entry.access) == (DataType.UNSIGNED16, Access.RW)


def test_mm4_sync_cob_id_default_is_0x80000080(registry: ProfileRegistry) -> None:
    """'8000080H' has a dropped digit: 0x80000080, bit 31 = DS301 SYNC consumer, COB-ID 0x80."""
    assert default(registry, MM4, "0x1005") == 0x80000080


def test_mm4_status_word_default_is_0(registry: ProfileRegistry) -> None:
    """Object table: 0x6041 default 0 (0xFE31 is the trace's value once the drive is ready)."""
    assert default(registry, MM4, "0x6041") == 0


def test_ethercat_c00876_1_is_an_rpdo_input(registry: ProfileRegistry) -> None:
    """§9.2: the only mapping example writes 0x5C930110 (C00876/1) into RxPDO 0x1600 sub 1: written by an RxPDO."""
    entry = catalog(registry, ETHERCAT).resolve("C00876/1").entry
    assert entry.access is Access.RWW and entry.access.writable and entry.pdo_mappable
    assert entry.access == catalog(registry, MOTEC).resolve("C00876/1").entry.access


def test_ethercat_strings_fit_their_printed_length(registry: ProfileRegistry) -> None:
    """§9.3: 0x1008 STRING(8), 0x1009 STRING(8), 0x100A STRING(7)."""
    profile: Profile = registry.get(ETHERCAT)
    lengths = {o.index: len(str(o.default)) for o in profile.objects if o.data_type is DataType.VISIBLE_STRING}
    printed = {o.index: int(m.group(1)) for o in profile.objects
               if (m := re.search(r"STRING\((\d+)\)", o.description or ""))}
    assert printed[0x100A] == 7 and lengths[0x100A] == 7
    assert all(lengths[index] <= size for index, size in printed.items())


@pytest.mark.parametrize("profile_id", [VECTOR, SERVO])
def test_emf_codes_lie_between_0x40c0_and_0x5fff(registry: ProfileRegistry, profile_id: str) -> None:
    """EMF2178IB §10.1: 'The index for Lenze code numbers is between 16576 (0x40C0) and 24575 (0x5FFF)'."""
    profile = registry.get(profile_id)
    addressing = profile.addressing
    assert isinstance(addressing, CodeAddressing)
    assert code_to_index(addressing, 7999) == (0x40C0, 0) and code_to_index(addressing, 0) == (0x5FFF, 0)
    with pytest.raises(UnknownParameter, match="0x40C0 and 0x5FFF"):
        code_to_index(addressing, 8000)
    assert index_to_code(addressing, 0x40C0, 0) == (7999, 0)
    assert index_to_code(addressing, 0x40BF, 0) is None and index_to_code(addressing, 0x2000, 0) is None
    with pytest.raises(UnknownParameter):
        Catalog(profile).resolve("C9000")


def test_8400_codes_keep_their_wider_range(registry: ProfileRegistry) -> None:
    """The 8400 codes reach below 0x40C0 (EtherCAT C13902 = 0x29B1)."""
    addressing = registry.get(ETHERCAT).addressing
    assert isinstance(addressing, CodeAddressing)
    assert code_to_index(addressing, 13902) == (0x29B1, 0)
