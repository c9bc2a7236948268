"""A zip of a vendor folder with broken members through the real API: each refused row names the archive, the
member's path and the line the reason is about (EDS and XDD alike)."""

from __future__ import annotations

import io
import zipfile

import pytest
from fastapi.testclient import TestClient

from tests.device.quirk_corpus import BASE

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_refused_members_of_a_zip_are_named_with_their_path_and_line(api: TestClient) -> None:
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w") as members:
        members.writestr("Vendor/EDS/junk.eds", "[DeviceInfo]\nVendorName=Example\n\n\x01\x02\x7f\x03\n")
        members.writestr("Vendor/XML/cut.xdd", "<?xml version='1.0'?>\n<a>\n<b></a>\n")
        members.writestr("Vendor/EDS/good.eds", BASE)
    response = api.post("/api/profiles/batch", files={"files": ("vendor.zip", archive.getvalue())})
    assert response.status_code == 200, response.text
    rows = {row["file"]: row for row in response.json()["rows"]}
    assert rows["vendor.zip/Vendor/EDS/good.eds"]["outcome"] == "accepted"
    junk, cut = rows["vendor.zip/Vendor/EDS/junk.eds"], rows["vendor.zip/Vendor/XML/cut.xdd"]
    assert junk["outcome"] == cut["outcome"] == "refused"
    assert (junk["line"], cut["line"]) == (4, 3)
    assert "binary junk" in junk["reason"] and "not well-formed XML" in cut["reason"]
