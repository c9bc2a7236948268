"""CiA 311 XDD/XDC: hand-written files, safe XML parsing, and export that reads back to the same profile."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivebench.device.build_eds import shipped_profiles
from drivebench.device.eds import read_eds
from drivebench.device.eds_export import export_eds
from drivebench.device.profile import ObjectEntry, Profile
from drivebench.device.xdd import read_xdd
from drivebench.device.xdd_export import export_xdd
from drivebench.errors import ProfileError
from tests.device.quirk_corpus import CORPUS_FILES

DATA = Path(__file__).resolve().parents[1] / "data" / "xdd"


def load(name: str) -> Profile:
    return read_xdd((DATA / name).read_bytes(), source=name).profile


def obj(profile: Profile, index: int, sub: int = 0) -> ObjectEntry:
    return next(o for o in profile.objects if (o.index, o.subindex) == (index, sub))


def test_servo_objects_take_what_they_leave_out_from_parameters_and_templates() -> None:
    imported = read_xdd((DATA / "servo_parameters.xdd").read_bytes(), source="servo_parameters.xdd")
    servo = imported.profile
    ident = servo.identity
    assert (ident.vendor_name, ident.vendor_id, ident.product_name, ident.product_code) == (
        "Example Drives", 0x4D2, "Servo 700", 0x2BC)
    assert ident.order_codes == ["SV-700-A", "SV-700-B"] and ident.device_type == 0x20192
    speed = obj(servo, 0x2000)
    assert (speed.name, speed.default, speed.min, speed.max, speed.unit) == ("Speed limit", 3000, 0, 8000, "rpm")
    assert speed.description == "Highest speed the drive accepts, in rpm." and speed.pdo_mappable
    assert obj(servo, 0x6040).name == "Controlword" and obj(servo, 0x6040).access.value == "rww"
    assert obj(servo, 0x1800, 1).default_expr == "$NODEID+0x180"
    assert [o.subindex for o in servo.objects if o.index == 0x1800] == [0, 1, 5]
    assert obj(servo, 0x1F50, 1).data_type.value == "DOMAIN" and obj(servo, 0x1F50, 1).object_type == "ARRAY"
    assert obj(servo, 0x2001).min == -2147483648 and obj(servo, 0x2001).obj_flags == 1
    assert servo.features.baud_rates_kbit == [125, 250, 500, 1000] and servo.features.tpdo_count == 1
    assert [(w.line, w.key) for w in imported.warnings] == [(82, "LowLimit")]


def test_xdc_actual_values_become_the_configured_values() -> None:
    node = load("io_node12.xdc")
    assert obj(node, 0x1017).parameter_value == 500
    assert obj(node, 0x1800, 1).parameter_value == 0x18C
    assert (obj(node, 0x6200, 1).parameter_value, obj(node, 0x6200, 1).denotation) == (0x0F, "Conveyor lamps")
    assert node.extra_sections["DeviceComissioning"] == {
        "NodeID": "12", "NodeName": "Conveyor IO", "Baudrate": "250", "NetNumber": "1", "NetworkName": "Line 2",
        "CANopenManager": "false"}
    assert node.features.baud_rates_kbit == [250, 1000]


def test_quirks_of_generated_xdd_are_read_with_warnings_naming_the_line() -> None:
    imported = read_xdd((DATA / "quirks.xdd").read_bytes(), source="quirks.xdd")
    found = {(w.line, w.key): w.message for w in imported.warnings}
    assert "is not 4 hex digits: skipped" in found[(19, "index")]
    assert "names no parameter" in found[(20, "uniqueIDRef")]
    assert "read as 65535" in found[(20, "HighLimit")]
    assert "is not hex: skipped" in found[(23, "subIndex")]
    assert "not a bit rate" in found[(27, "baudRate")]
    assert {o.index for o in imported.profile.objects} == {0x1000, 0x2000, 0x2001}


BAD_XML = [
    ("xxe", b'<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n'
            b"<ISO15745ProfileContainer>&e;</ISO15745ProfileContainer>", 2, "DOCTYPE or ENTITY"),
    ("billion laughs", b'<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lol">\n'
                       b' <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">\n]>\n<lolz>&lol2;</lolz>',
     2, "DOCTYPE or ENTITY"),
    ("not well-formed", b"<?xml version='1.0'?>\n<ISO15745ProfileContainer>\n<a>\n</ISO15745ProfileContainer>", 4,
     "not well-formed XML"),
    ("deeply nested", b"<ISO15745ProfileContainer>" + b"<a>" * 100_000 + b"</a>" * 100_000
     + b"</ISO15745ProfileContainer>", 1, "not well-formed XML"),
    ("other root", b"<?xml version='1.0'?>\n<html><body/></html>", 2, "root element is <html>"),
    ("no object list", b"<ISO15745ProfileContainer><ISO15745Profile/></ISO15745ProfileContainer>", 1,
     "no object dictionary"),
    ("random bytes", bytes(range(256)) * 8, 1, "not well-formed XML"),
]


@pytest.mark.parametrize(("what", "content", "line", "words"), BAD_XML, ids=[b[0] for b in BAD_XML])
def test_unsafe_or_broken_xml_is_refused_with_line_and_reason(what: str, content: bytes, line: int,
                                                              words: str) -> None:
    with pytest.raises(ProfileError) as caught:
        read_xdd(content, source="bad.xdd")
    assert caught.value.source == "bad.xdd" and words in caught.value.detail
    assert caught.value.line == line


@pytest.mark.parametrize(("name", "content"), [(n, c) for n, c, _ in CORPUS_FILES[::3]])
def test_xdd_of_a_corpus_profile_reads_back_to_the_same_objects(name: str, content: bytes) -> None:
    profile = read_eds(content, source=name).profile
    again = read_xdd(export_xdd(profile), source=name)
    assert again.warnings == []
    assert again.profile.objects == profile.objects and again.profile.identity == profile.identity
    assert again.profile.features.baud_rates_kbit == profile.features.baud_rates_kbit


@pytest.mark.parametrize("profile", shipped_profiles(), ids=lambda p: p.id)
def test_xdd_of_a_shipped_profile_holds_what_its_eds_holds(profile: Profile) -> None:
    """Vendor parameters, factors, units and descriptions go through XDD like through EDS."""
    via_xdd = read_xdd(export_xdd(profile), source=f"{profile.id}.xdd").profile
    via_eds = read_eds(export_eds(profile), source=f"{profile.id}.eds").profile
    assert via_xdd.objects == via_eds.objects


def test_xdc_of_node_values_reads_back_as_parameter_values() -> None:
    servo = load("servo_parameters.xdd")
    xdc = export_xdd(servo, node_id=9, values={(0x2000, 0): 4500, (0x1017, 0): 250}, xdc=True, baud_kbit=500)
    node = read_xdd(xdc, source="node9.xdc").profile
    assert (obj(node, 0x2000).parameter_value, obj(node, 0x1017).parameter_value) == (4500, 250)
    assert obj(node, 0x1800, 1).parameter_value == 0x189  # $NODEID resolved for node 9
    assert obj(node, 0x1800, 1).default_expr == "$NODEID+0x180"
    assert node.extra_sections["DeviceComissioning"]["NodeID"] == "9"
    assert node.extra_sections["DeviceComissioning"]["Baudrate"] == "500"
