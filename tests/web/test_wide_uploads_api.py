"""UTF-16/32 EDS with a big-endian byte order mark through the real API (the corpus has LE with and without BOM and
BE without): read like the UTF-8 file, without a warning."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.device.quirk_corpus import BASE

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.mark.parametrize(("bom", "encoding"), [(b"\xfe\xff", "utf-16-be"), (b"\x00\x00\xfe\xff", "utf-32-be")])
def test_a_big_endian_eds_with_bom_reads_like_its_utf8_twin(api: TestClient, bom: bytes, encoding: str) -> None:
    wide = api.post("/api/profiles", files={"file": ("wide.eds", bom + BASE.replace("\n", "\r\n").encode(encoding))})
    assert wide.status_code == 201, wide.text
    twin = api.post("/api/profiles", files={"file": ("twin.eds", BASE.encode())}).json()
    assert wide.json()["warnings"] == []
    assert {k: wide.json()[k] for k in ("objects", "parameters", "vendor", "product")} == \
        {k: twin[k] for k in ("objects", "parameters", "vendor", "product")}
