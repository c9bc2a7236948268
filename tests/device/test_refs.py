"""Parameter references as the catalog writes them read back as the same object (a subindex of two digits too:
the 8400 motec EtherCAT unit's TxPDO mapping 0x1A00 has entries 1 ... 10)."""

from __future__ import annotations

import pytest

from drivebench.device.profiles.addressing import IndexRef, parse_ref
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import UnknownParameter


def test_every_catalog_ref_resolves_to_its_own_item(registry: ProfileRegistry) -> None:
    for profile in registry.all():
        catalog = Catalog(profile)
        for item in catalog.items:
            assert catalog.resolve(item.ref) is item, f"{profile.id}: {item.ref}"


@pytest.mark.parametrize(("text", "sub"), [("0x1A00.10", 10), ("0x1A00sub10", 10), ("0x1A00.0A", 10),
                                           ("0x1A00.0x10", 16), ("0x1003:0f", 15), ("0x1600.255", 255)])
def test_a_subindex_is_decimal_unless_written_in_hex(text: str, sub: int) -> None:
    assert parse_ref(text) == IndexRef(int(text[2:6], 16), sub)


def test_a_subindex_above_255_is_refused() -> None:
    with pytest.raises(UnknownParameter, match="Subindex 300 is more than 255"):
        parse_ref("0x1600.300")
