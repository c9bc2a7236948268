"""Info tab: identity objects in words and decimal (UX bar 2), the raw value one hover away."""

from __future__ import annotations

from fastapi.testclient import TestClient

from drivebench.web.pages.node_info import identity_text, shown


def test_device_type_names_the_cia_profile() -> None:
    assert identity_text("0x1000", 0x00010192) == "CiA 402 drives and motion control, additional information 1"
    assert identity_text("0x1000", 0) == "no standard device profile"


def test_revision_is_major_minor_in_decimal_and_serial_is_decimal() -> None:
    assert identity_text("0x1018.3", 0x00020011) == "2.17 (major.minor)"
    assert identity_text("0x1018.4", 0x00012345) == "74565"
    assert shown("Serial number", "0x1018.4", 0x00012345).raw_hex == "0x00012345"


def test_vendor_named_only_when_the_profile_vendor_matches() -> None:
    assert identity_text("0x1018.1", 0x3B, (0x3B, "Lenze")) == "0x0000003B · Lenze"
    assert identity_text("0x1018.1", 0x3B, (0x53, "Siemens")) == "0x0000003B"
    assert identity_text("0x1018.2", None) == "–"


def test_info_read_shows_the_device_identity_in_words(client: TestClient) -> None:
    page = client.post("/ui/sessions/demo-plant/nodes/3/info/read", headers={"HX-Request": "true"})
    assert page.status_code == 200
    assert "CiA 402 drives and motion control" in page.text  # MICROMASTER 0x1000 = 0x00010192
    assert 'title="raw 0x00010192"' in page.text
    assert "74565" in page.text  # the simulated serial number 0x00012345 in decimal
