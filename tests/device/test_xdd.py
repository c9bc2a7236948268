"""CiA 311 XDD/XDC: hand-written files, safe XML parsing, and export that reads back to the same profile."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivebench.device.formats.build_eds import shipped_profiles
from drivebench.device.formats.eds import read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.device.profiles.profile import ObjectEntry, Profile
from drivebench.errors import ProfileError
from tests.device.profile_strategies import profiles, raw_value
from tests.device.quirk_corpus import BASE, CORPUS_FILES
from tests.device.test_eds_quirks import not_of_kept_texts

DATA = Path(__file__).resolve().parents[1] / "data" / "xdd"
DATA_EDS = DATA.parent / "eds"


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


def test_objects_typed_only_by_their_parameters_take_type_access_values_and_denotation_from_them() -> None:
    """An XDD as object dictionary editors write it: the CANopenObject names its parameter, which holds the IEC
    type, the access, default, range, actual value and denotation (the heads' dataTypeIDRef types are skipped)."""
    imported = read_xdd((DATA / "typed_parameters.xdd").read_bytes(), source="typed_parameters.xdd")
    io = imported.profile
    assert imported.warnings == []
    rows = [(o.index, o.subindex, o.data_type.value, o.access.value, o.default) for o in io.objects]
    assert rows == [(0x1000, 0, "UNSIGNED32", "ro", 0x30191), (0x1017, 0, "UNSIGNED16", "rw", 0),
                    (0x1018, 0, "UNSIGNED8", "ro", 1), (0x1018, 1, "UNSIGNED32", "ro", 0x321),
                    (0x1F50, 0, "UNSIGNED8", "ro", 1), (0x1F50, 1, "DOMAIN", "wo", None),
                    (0x6200, 0, "UNSIGNED8", "rww", 0)]
    heartbeat = obj(io, 0x1017)
    assert (heartbeat.min, heartbeat.max, heartbeat.parameter_value) == (0, 60000, 100)
    assert (heartbeat.denotation, heartbeat.description) == ("Heartbeat of the door IO", "Heartbeat period in ms.")
    assert obj(io, 0x6200).pdo_mappable and not obj(io, 0x1000).pdo_mappable
    assert all(o.object_keys is None for o in io.objects) and io.version == "1.1"


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


def what_xdd_holds(profile: Profile) -> dict[str, object]:
    """The part of a profile CiA 311 can express: the object dictionary (every field of every entry; the EDS
    CompactSubObj layout and the EDS DataType code of a type the model reads as another aside), identity, bit
    rates, PDO counts, and the header's revision and source."""
    objects = sorted((o.model_copy(update={"compact": False, "data_type_code": None}) for o in profile.objects),
                     key=lambda o: (o.index, o.subindex))
    features = profile.features
    return {"objects": objects, "identity": profile.identity, "version": profile.version, "source": profile.source,
            "features": (features.baud_rates_kbit, features.rpdo_count, features.tpdo_count)}


EDS_FILES = [(n, c) for n, c, _ in CORPUS_FILES] + [(p.name, p.read_bytes()) for p in sorted(DATA_EDS.iterdir())]


@pytest.mark.parametrize(("name", "content"), EDS_FILES, ids=[n for n, _ in EDS_FILES])
def test_xdd_of_an_imported_file_reads_back_to_the_same_profile(name: str, content: bytes) -> None:
    """Every quirk corpus file and every test EDS/DCF: EDS -> profile -> XDD -> the same profile, without a
    warning; and its regenerated EDS (not the kept bytes) reads back to the same profile too."""
    profile = read_eds(content, source=name).profile
    again = read_xdd(export_xdd(profile), source=name)
    assert not_of_kept_texts(again.warnings) == []  # a value kept as the file wrote it is read so again
    assert what_xdd_holds(again.profile) == what_xdd_holds(profile)
    assert read_eds(export_eds(again.profile), source=name).profile.objects == again.profile.objects


@pytest.mark.parametrize("profile", shipped_profiles(), ids=lambda p: p.id)
def test_a_shipped_profile_goes_through_eds_and_xdd_to_the_same_profile(profile: Profile) -> None:
    """Vendor parameters, factors, units and descriptions go through XDD like through EDS; the profile read from
    either goes through both again unchanged."""
    via_eds = read_eds(export_eds(profile), source=f"{profile.id}.eds").profile
    via_xdd = read_xdd(export_xdd(profile), source=f"{profile.id}.xdd").profile
    assert what_xdd_holds(via_xdd) == what_xdd_holds(via_eds)
    assert read_eds(export_eds(via_eds), source=f"{profile.id}.eds").profile == via_eds
    assert what_xdd_holds(read_xdd(export_xdd(via_xdd), source="again.xdd").profile) == what_xdd_holds(via_xdd)


@pytest.mark.slow  # measured 54-120 s of the quick subset on the loaded 2 cores
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(profiles())
def test_import_of_xdd_export_is_the_same_profile(profile: Profile) -> None:
    again = read_xdd(export_xdd(profile), source="generated.xdd")
    assert again.warnings == []
    assert what_xdd_holds(again.profile) == what_xdd_holds(profile)


@st.composite
def _node_values(draw: st.DrawFn) -> tuple[Profile, int, dict[tuple[int, int], int | float | str]]:
    profile = draw(profiles())
    chosen = draw(st.lists(st.sampled_from(profile.objects), unique_by=lambda o: (o.index, o.subindex), max_size=6))
    return profile, draw(st.integers(1, 127)), {(o.index, o.subindex): draw(raw_value(o.data_type, 1))
                                                for o in chosen}


@pytest.mark.slow  # measured 54-120 s of the quick subset on the loaded 2 cores
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_node_values())
def test_xdc_of_node_values_reads_back_like_the_dcf_of_them(
        case: tuple[Profile, int, dict[tuple[int, int], int | float | str]]) -> None:
    """A node's values written as XDC (actualValue, deviceCommissioning) read back as the configured values the
    DCF of the same values gives, $NODEID formulas resolved for that node."""
    profile, node_id, values = case
    xdc = read_xdd(export_xdd(profile, node_id=node_id, values=values, xdc=True, baud_kbit=250), source="n.xdc")
    dcf = read_eds(export_eds(profile, node_id=node_id, values=values, dcf=True, baud_kbit=250), source="n.dcf")
    assert xdc.warnings == [] and what_xdd_holds(xdc.profile)["objects"] == what_xdd_holds(dcf.profile)["objects"]
    commissioning = xdc.profile.extra_sections["DeviceComissioning"]
    assert (commissioning["NodeID"], commissioning["Baudrate"]) == (str(node_id), "250")


def test_a_data_type_the_data_type_list_defines_is_read_as_its_basic_type() -> None:
    xml = export_xdd(read_eds(BASE, source="base.eds").profile).decode()
    assert re.search(r'<defType dataType="0007">\s*<Unsigned32/>', xml)
    xml = xml.replace("<dataTypeList>", '<dataTypeList><defType dataType="0040"><Unsigned32/></defType>')
    xml, replaced = re.subn(r'(index="2000" name="Speed limit" objectType="7") dataType="0007"', r'\1 dataType="0040"',
                            xml)
    imported = read_xdd(xml.encode(), source="types.xdd")
    assert replaced == 1 and obj(imported.profile, 0x2000).data_type.value == "UNSIGNED32"
    assert [w.key for w in imported.warnings] == ["dataType"]
    assert "dataType=0040 is defined in the dataTypeList: read as UNSIGNED32" in imported.warnings[0].message


def test_xdc_of_node_values_reads_back_as_parameter_values() -> None:
    servo = load("servo_parameters.xdd")
    xdc = export_xdd(servo, node_id=9, values={(0x2000, 0): 4500, (0x1017, 0): 250}, xdc=True, baud_kbit=500)
    node = read_xdd(xdc, source="node9.xdc").profile
    assert (obj(node, 0x2000).parameter_value, obj(node, 0x1017).parameter_value) == (4500, 250)
    assert obj(node, 0x1800, 1).parameter_value == 0x189  # $NODEID resolved for node 9
    assert obj(node, 0x1800, 1).default_expr == "$NODEID+0x180"
    assert node.extra_sections["DeviceComissioning"]["NodeID"] == "9"
    assert node.extra_sections["DeviceComissioning"]["Baudrate"] == "500"
