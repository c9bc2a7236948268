"""Factory values (issue 30 item 5): the profile's default scaled to raw, a ``$NODEID`` formula for the node, CiA
301's pre-defined connection set where a profile gives no default, and None (never a guess) where no source gives
one; words that read in hex."""

from __future__ import annotations

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.factory_default import factory_raw, same_raw
from drivebench.device.profiles.number_base import hex_word, shows_hex
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.protocol.datatypes import DataType


def _entry(index: int, sub: int = 0, data_type: DataType = DataType.UNSIGNED32, **fields: object) -> ObjectEntry:
    return ObjectEntry(name="x", data_type=data_type, access=Access.RW, index=index, subindex=sub, **fields)


def test_a_default_in_engineering_units_becomes_raw() -> None:
    assert factory_raw(_entry(0x2000, factor=100, default=10.2), 5, 0x2000, 0) == 1020
    assert factory_raw(_entry(0x2001, data_type=DataType.REAL32, factor=1, default=1.5), 5, 0x2001, 0) == 1.5


def test_a_nodeid_formula_and_the_predefined_connection_set_name_the_node() -> None:
    assert factory_raw(_entry(0x1800, 1, default_expr="$NODEID+0x40000180"), 5, 0x1800, 1) == 0x40000185
    assert factory_raw(_entry(0x1801, 1), 7, 0x1801, 1) == 0x287
    assert factory_raw(_entry(0x1200, 2), 7, 0x1200, 2) == 0x587


def test_no_source_no_factory_value() -> None:
    assert factory_raw(_entry(0x2002), 5, 0x2002, 0) is None
    assert factory_raw(_entry(0x1804, 1), 5, 0x1804, 1) is None  # beyond the pre-defined connection set


def test_same_raw_tolerates_float_rounding_and_trailing_nuls() -> None:
    assert same_raw(0.1 + 0.2, 0.3) and not same_raw(1.0, 1.1)
    assert same_raw("abc\x00", "abc") and same_raw(b"\x01\x02", "0102")
    assert not same_raw(5, "5")


def test_cob_ids_identity_and_mapping_entries_read_in_hex_amounts_do_not() -> None:
    def item(index: int, sub: int, data_type: DataType = DataType.UNSIGNED32, **fields: object) -> Item:
        return Item(f"0x{index:04X}.{sub}", index, sub, _entry(index, sub, data_type, **fields))

    assert all(shows_hex(item(i, s)) for i, s in [(0x1000, 0), (0x1005, 0), (0x1014, 0), (0x1018, 1), (0x1018, 4),
                                                   (0x1200, 1), (0x1280, 2), (0x1400, 1), (0x1803, 1), (0x1A00, 1)])
    assert not any(shows_hex(item(i, s, DataType.UNSIGNED8 if s == 0 else DataType.UNSIGNED16))
                   for i, s in [(0x1018, 0), (0x1800, 2), (0x1800, 5), (0x1017, 0), (0x1A00, 0)])
    assert not shows_hex(item(0x2000, 0))
    assert shows_hex(item(0x2000, 0, hex=True)) and shows_hex(item(0x2001, 0, DataType.UNSIGNED16, bits={0: "on"}))
    assert not shows_hex(item(0x1800, 1, factor=10)), "a scaled value is an amount"
    assert hex_word(item(0x1800, 1), 0x185) == "0x00000185"
    assert hex_word(item(0x2003, 0, DataType.INTEGER16), -2) == "0xFFFE"
