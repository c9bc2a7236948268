"""EDS/DCF import and export: real-world style files, bad files with file and line, and property round trips."""

from __future__ import annotations

import io
from pathlib import Path

import canopen
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivebench.device.formats.eds import MAX_EDS_BYTES, import_eds, read_eds, resolve_node_expr
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles.profile import (
    Access,
    CodeAddressing,
    Identity,
    ObjectEntry,
    Parameter,
    ParameterNumberAddressing,
    Profile,
)
from drivebench.errors import ProfileError, UnknownParameter
from drivebench.protocol.datatypes import DataType
from tests.device.profile_strategies import profiles, raw_value

DATA = Path(__file__).resolve().parents[1] / "data" / "eds"
REAL_FILES = sorted(p.name for p in DATA.iterdir() if p.suffix.lower() in (".eds", ".dcf"))
CANOPEN_UNREADABLE = {"generic_quirks.eds"}  # canopen 2.4.1: int('', 0) on an empty VendorNumber=


def load(name: str) -> Profile:
    return import_eds(DATA / name, source=name)


def obj(profile: Profile, index: int, sub: int = 0) -> ObjectEntry:
    return next(o for o in profile.objects if (o.index, o.subindex) == (index, sub))


# --- real-world style files ---------------------------------------------------------------------------
def test_cia402_servo_identity_features_and_kept_sections() -> None:
    servo = load("cia402_servo.eds")
    assert servo.id == "cia402_servo"
    assert servo.identity == Identity(vendor_name="Example Motion GmbH", vendor_id=0x1AB, product_name="EM-Servo 400",
                                      product_code=0x4002, revision=0x10003,
                                      order_codes=["EMS-400-CAN", "EMS-400-CAN-S"], device_type=0x20192)
    assert servo.features.baud_rates_kbit == [125, 250, 500, 1000]
    assert (servo.features.rpdo_count, servo.features.tpdo_count) == (2, 2)
    assert servo.features.heartbeat_consumers == 2
    assert servo.notes[1] == "Limits of 0x607A are given as two's complement hex."
    assert servo.extra_sections["Tools"] == {"Items": "1", "Tool1": "Example Motion Configurator"}
    assert servo.extra_sections["DeviceInfo"] == {"LSS_Supported": "1"}
    assert servo.extra_sections["FileInfo"]["CreationDate"] == "03-14-2024"
    assert servo.extra_sections["DummyUsage"]["Dummy0002"] == "1"


def test_cia402_servo_objects() -> None:
    servo = load("cia402_servo.eds")
    assert obj(servo, 0x1014).default_expr == "$NODEID+0x80" and obj(servo, 0x1014).default is None
    assert obj(servo, 0x1200, 2).default_expr == "0x580+$NODEID"
    assert obj(servo, 0x1017).parameter_value == 100  # "0144" is octal
    compact = [o for o in servo.objects if o.index == 0x1016]
    assert [(o.subindex, o.name) for o in compact] == [
        (0, "NrOfObjects"), (1, "Consumer heartbeat time (master)"), (2, "Consumer heartbeat time (PLC)")]
    assert compact[0].default == 2 and compact[2].data_type is DataType.UNSIGNED32
    assert {o.obj_flags for o in servo.objects if o.index == 0x1010} == {1}
    assert obj(servo, 0x607A).min == -0x80000000 and obj(servo, 0x607A).max == 0x7FFFFFFF
    assert obj(servo, 0x6060).data_type is DataType.INTEGER8 and obj(servo, 0x6060).min == -10
    rated = obj(servo, 0x2000, 2)
    assert (rated.default, rated.max, rated.unit, rated.factor) == (10.2, 50.0, "A", 100)
    assert obj(servo, 0x2000, 3).default == 1.25
    domain = obj(servo, 0x2001)
    assert (domain.data_type, domain.object_type, domain.access, domain.default) == (
        DataType.DOMAIN, "VAR", Access.WO, None)
    assert obj(servo, 0x2002).default == "Generic PMSM motor 400W"


def test_latin1_dcf_with_compact_values_and_denotations() -> None:
    dcf = load("io_module_node12.dcf")
    assert dcf.identity.product_name == "IO-16 Temperaturmodul"
    assert dcf.extra_sections["DeviceComissioning"]["NodeID"] == "12"
    assert obj(dcf, 0x2100).denotation == "Kalibrierung Fühler 1"
    assert obj(dcf, 0x2100).parameter_value == -1.5
    assert obj(dcf, 0x6400, 1).denotation == "Ofentemperatur oben (°C)"
    assert [obj(dcf, 0x6400, s).parameter_value for s in (1, 2, 3, 4)] == [-3, None, None, 127]
    assert obj(dcf, 0x1800, 1).parameter_value == "$NODEID+0x180"
    assert obj(dcf, 0x2101).default == "00 11 22 AA"
    assert {o.obj_flags for o in dcf.objects if o.index == 0x6401} == {2}


def test_lenze_file_with_crlf_decimal_types_and_spaced_formula() -> None:
    lenze = load("lenze_8400_motec.eds")
    assert lenze.identity.vendor_id == 0x3B
    assert lenze.features.baud_rates_kbit == [20, 50, 125, 250, 500, 800, 1000]
    assert obj(lenze, 0x5FA7).name == "C00088: Rated motor current"
    assert obj(lenze, 0x5FA7).default == 10.2  # 1020 raw, Factor=100
    assert obj(lenze, 0x1014).default_expr == "$NODEID + 0x80"
    assert resolve_node_expr("$NODEID + 0x80", 2) == 0x82


@pytest.mark.parametrize("name", REAL_FILES)
def test_real_files_round_trip(name: str) -> None:
    profile = load(name)
    assert import_eds(export_eds(profile), source=name) == profile


@pytest.mark.parametrize("name", sorted(set(REAL_FILES) - CANOPEN_UNREADABLE))
def test_canopen_reads_our_dcf_like_the_original(name: str) -> None:
    """canopen (an independent reader) sees the same defaults and resolved values in our DCF as in the file."""
    original = _canopen_od((DATA / name).read_bytes().decode("latin-1"), name)
    ours = _canopen_od(export_eds(load(name), node_id=5, dcf=True, baud_kbit=500), "ours.dcf")
    for index in original:
        if index < 0x1000:
            continue
        theirs = original[index]
        members = [theirs] if isinstance(theirs, canopen.objectdictionary.ODVariable) else list(theirs.values())
        for var in members:
            mine = ours[index][var.subindex] if var.subindex or not isinstance(
                theirs, canopen.objectdictionary.ODVariable) else ours[index]
            assert (mine.data_type, mine.min, mine.max) == (var.data_type, var.min, var.max), (hex(index), var.subindex)
            if var.default is not None:  # canopen leaves a CompactSubObj sub 0 without default; we give N
                assert mine.default == var.default, (hex(index), var.subindex)
            if var.value is not None:
                assert mine.value == var.value, (hex(index), var.subindex)


def test_generic_file_quirks() -> None:
    """Generated EDS files in the wild leave identity fields empty, count comment lines as 0, comment out tool keys,
    write formulas constant first or with the 'disabled' bit, skip sub-indices and mix cases and number bases."""
    quirks = load("generic_quirks.eds")
    assert (quirks.identity.vendor_name, quirks.identity.vendor_id, quirks.identity.product_code) == ("", None, None)
    assert quirks.notes == [] and quirks.features.baud_rates_kbit == [125, 500]
    assert obj(quirks, 0x1014).default_expr == "0x80+$NODEID"
    assert resolve_node_expr(obj(quirks, 0x1400, 1).default_expr or "", 5) == 0x80000205
    assert [o.subindex for o in quirks.objects if o.index == 0x1400] == [0, 1, 5]
    assert (obj(quirks, 0x1001).data_type, obj(quirks, 0x1001).access) == (DataType.UNSIGNED8, Access.RO)
    assert obj(quirks, 0x1018, 1).default is None  # "DefaultValue=" with nothing after it
    assert obj(quirks, 0x1A00, 1).default == 0x30040110
    sampling = obj(quirks, 0x3002)
    assert (sampling.default, sampling.min, sampling.parameter_value) == (pytest.approx(5.2), 4.5, pytest.approx(5.2))
    assert [o.name for o in quirks.objects if o.index == 0x3004] == [
        "NrOfObjects", "Status left", "Status middle", "Status right"]
    # canopen cannot read the original (empty VendorNumber=), but it reads our DCF of it
    ours = _canopen_od(export_eds(quirks, node_id=5, dcf=True), "ours.dcf")
    assert ours[0x1400][1].value == 0x80000205 and ours[0x1014].value == 0x85


def _canopen_od(text: str, name: str) -> canopen.ObjectDictionary:
    stream = io.StringIO(text)
    stream.name = name
    return canopen.import_od(stream, node_id=5)


# --- DCF export -----------------------------------------------------------------------------------------
def test_dcf_for_a_node_resolves_formulas_and_writes_values() -> None:
    servo = load("cia402_servo.eds")
    text = export_eds(servo, node_id=5, dcf=True, baud_kbit=250, values={(0x1017, 0): 250, (0x2000, 1): 7})
    assert "[DeviceComissioning]\nNodeID=5\nBaudrate=250\n" in text
    again = import_eds(text, source="servo_node5.dcf")
    assert obj(again, 0x1014).parameter_value == 0x85
    assert obj(again, 0x1014).default_expr == "$NODEID+0x80"  # the DCF still works for another node id
    assert obj(again, 0x1801, 1).parameter_value == 0x40000285
    assert obj(again, 0x1017).parameter_value == 250
    assert obj(again, 0x2000, 1).parameter_value == 7
    assert again.extra_sections["DeviceComissioning"] == {"NodeID": "5", "Baudrate": "250"}


def test_dcf_values_for_unknown_objects_are_refused() -> None:
    with pytest.raises(UnknownParameter, match="0x2FFFsub0"):
        export_eds(load("cia402_servo.eds"), dcf=True, values={(0x2FFF, 0): 1})


def _vendor_profile(addressing: CodeAddressing | ParameterNumberAddressing) -> Profile:
    lenze = isinstance(addressing, CodeAddressing)
    code = "C00088" if lenze else "P0305"
    return Profile(
        id="vendor-test", family="test", addressing=addressing,
        identity=Identity(vendor_name="Lenze", vendor_id=0x3B, product_name="8400", product_code=0x84D0),
        parameters=[
            Parameter(code=code, name="Rated motor current", data_type=DataType.UNSIGNED16, factor=100, unit="A",
                      min=0, max=500, default=10.2, parameter_sets=2),
            Parameter(code="C00322" if lenze else "r0027", subcode=1, name="Transmission mode",
                      subcode_name="CAN1 OUT", data_type=DataType.UNSIGNED8, default=254),
            Parameter(code="C00322" if lenze else "r0027", subcode=2, name="Transmission mode",
                      subcode_name="CAN2 OUT", data_type=DataType.UNSIGNED8, default=254),
        ],
    )


def test_lenze_codes_become_manufacturer_objects_at_their_index() -> None:
    exported = import_eds(export_eds(_vendor_profile(CodeAddressing())), source="x.eds")
    assert obj(exported, 0x5FA7).name == "C00088: Rated motor current"
    assert (obj(exported, 0x5FA7).default, obj(exported, 0x5FA7).factor) == (10.2, 100)
    assert obj(exported, 0x5FFF - 2088).name == "C02088: Rated motor current (parameter set 2)"
    record = [o for o in exported.objects if o.index == 0x5FFF - 322]
    assert [(o.subindex, o.name) for o in record] == [
        (0, "Highest sub-index supported"), (1, "C00322/1: CAN1 OUT"), (2, "C00322/2: CAN2 OUT")]
    assert record[0].object_name == "C00322: Transmission mode" and record[0].default == 2
    assert {0x1000, 0x1001, 0x1018} <= {o.index for o in exported.objects}
    assert obj(exported, 0x1018, 1).default == 0x3B


def test_siemens_parameters_use_their_index() -> None:
    exported = import_eds(export_eds(_vendor_profile(ParameterNumberAddressing())), source="x.eds")
    assert obj(exported, 0x2000 + 305).name == "P0305: Rated motor current"
    assert obj(exported, 0x2000 + 27, 2).name == "r0027.2: CAN2 OUT"


# --- bad files ------------------------------------------------------------------------------------------
GOOD = """[FileInfo]
FileName=bad.eds
[DeviceInfo]
VendorName=V
ProductName=P
[MandatoryObjects]
SupportedObjects=2
1=0x1000
2=0x1018
[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0
[1018]
ParameterName=Identity object
ObjectType=0x9
SubNumber=2
[1018sub0]
ParameterName=Highest sub-index supported
DataType=0x0005
AccessType=ro
DefaultValue=1
[1018sub1]
ParameterName=Vendor-ID
DataType=0x0007
AccessType=ro
DefaultValue=0x1AB
LowLimit=0
HighLimit=0xFFFF
"""


def line_of(text: str, needle: str, nth: int = 1) -> int:
    hits = [n for n, line in enumerate(text.splitlines(), start=1) if line.startswith(needle)]
    return hits[nth - 1]


def test_the_good_file_loads() -> None:
    assert obj(import_eds(GOOD, source="bad.eds"), 0x1018, 1).default == 0x1AB


QUIRKS = [
    # (what, old, new, line finder, words of the warning): each is read and noted, never refused
    ("truncated", "DataType=0x0007\nAccessType=ro\nDefaultValue=0x1AB\nLowLimit=0\nHighLimit=0xFFFF\n", "DataTy",
     lambda t: line_of(t, "DataTy", 3), "no '='"),
    ("truncated object", "[1018sub1]\nParameterName=Vendor-ID\nDataType=0x0007\nAccessType=ro\n"
     "DefaultValue=0x1AB\nLowLimit=0\nHighLimit=0xFFFF\n", "", lambda t: line_of(t, "SubNumber"),
     "SubNumber=2 but object 0x1018 has 1"),
    ("unknown data type", "DataType=0x0005", "DataType=0x0099", lambda t: line_of(t, "DataType=0x0099"),
     "DataType=0x0099 (no CiA 301 basic data type) is not a CiA 301 basic data type: read as DOMAIN"),
    ("text for a number", "DefaultValue=1\n", "DefaultValue=one\n", lambda t: line_of(t, "DefaultValue=one"),
     "not a number: dropped"),
    ("value too big", "DefaultValue=1\n", "DefaultValue=300\n", lambda t: line_of(t, "DefaultValue=300"),
     "does not fit UNSIGNED8"),
    ("duplicate section", "[1018sub1]", "[1018sub0]", lambda t: line_of(t, "[1018sub0]", 2),
     "duplicate section [1018sub0]"),
    ("duplicate key", "AccessType=ro\nDefaultValue=0\n", "AccessType=ro\naccesstype=rw\nDefaultValue=0\n",
     lambda t: line_of(t, "accesstype"), "the first value 'ro' is kept"),
    ("low above high", "LowLimit=0\n", "LowLimit=0x10000\n", lambda t: line_of(t, "HighLimit"),
     "limits dropped: LowLimit 0x10000 > HighLimit 0xFFFF"),
    ("binary junk", "[1000]\n", "[1000]\n\x00\x89PNG\x1a\n", lambda t: line_of(t, "\x00"), "binary junk"),
    ("missing ParameterName", "ParameterName=Device type\n", "", lambda t: line_of(t, "[1000]"),
     "[1000] has no ParameterName=: named 'Object 0x1000'"),
    ("missing AccessType", "AccessType=ro\nDefaultValue=0\n", "DefaultValue=0\n", lambda t: line_of(t, "[1000]"),
     "[1000] has no AccessType=: read as ro"),
    ("listed object without section", "2=0x1018\n", "2=0x1018\n3=0x1001\n", lambda t: line_of(t, "SupportedObj"),
     "SupportedObjects=2 but [MandatoryObjects] lists 3"),
    ("object without section", "SupportedObjects=2\n", "SupportedObjects=3\n3=0x1001\n",
     lambda t: line_of(t, "3=0x1001"), "no [1001] section: skipped"),
    ("bad formula", "DefaultValue=0x1AB", "DefaultValue=$NODEID*2", lambda t: line_of(t, "DefaultValue=$NODEID"),
     "is not a sum of numbers and $NODEID: dropped"),
    ("bad access", "AccessType=ro\nDefaultValue=0\n", "AccessType=rx\nDefaultValue=0\n",
     lambda t: line_of(t, "AccessType=rx"), "read as ro"),
    ("bad object type", "ObjectType=0x7", "ObjectType=0x5", lambda t: line_of(t, "ObjectType=0x5"),
     "type definition"),
    ("unterminated header", "[1000]", "[1000", lambda t: line_of(t, "[1000"), "has no ']': read as [1000]"),
    ("no DeviceInfo", "[DeviceInfo]\nVendorName=V\nProductName=P\n", "", lambda t: 1, "no [DeviceInfo]"),
    ("sub without object", "[1000]\n", "[2000sub1]\nParameterName=x\n[1000]\n",
     lambda t: line_of(t, "[2000sub1]"), "belongs to no object section [2000]: read as a RECORD"),
    ("key before section", "[FileInfo]\n", "Junk=1\n[FileInfo]\n", lambda t: 1, "before the first [section]"),
]


@pytest.mark.parametrize(("what", "old", "new", "find_line", "message"), QUIRKS, ids=[b[0] for b in QUIRKS])
def test_quirks_are_read_with_a_warning_naming_file_line_and_reading(what: str, old: str, new: str, find_line,
                                                                      message: str) -> None:
    assert old in GOOD, what
    text = GOOD.replace(old, new, 1)
    imported = read_eds(text, source="bad.eds")
    line = find_line(text)
    found = [w for w in imported.warnings if message in w.message]
    assert found, [w.text() for w in imported.warnings]
    assert (found[0].file, found[0].line) == ("bad.eds", line)
    assert found[0].text().startswith(f"bad.eds:{line}: ")
    assert read_eds(GOOD, source="good.eds").warnings == []


REFUSED = [
    ("no object section", "[FileInfo]\nFileName=x.eds\n[DeviceInfo]\nVendorName=V\n", 1, "no object dictionary"),
    ("empty", "", None, "no object dictionary"),
    ("random bytes", "\x00\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", 1, "binary junk"),
    ("only a type definition", "[0020]\nParameterName=PDO\nObjectType=0x6\n[1000]\nParameterName=T\n"
     "ObjectType=0x5\n", 1, "usable object"),
]


@pytest.mark.parametrize(("what", "text", "line", "message"), REFUSED, ids=[r[0] for r in REFUSED])
def test_a_file_without_object_dictionary_is_refused(what: str, text: str, line: int | None, message: str) -> None:
    with pytest.raises(ProfileError) as caught:
        import_eds(text, source="x.eds")
    assert caught.value.line == line and message in caught.value.detail


def test_oversized_file_is_refused_before_parsing(tmp_path: Path) -> None:
    big = tmp_path / "huge.eds"
    big.write_bytes(GOOD.encode() + b";" * MAX_EDS_BYTES)
    with pytest.raises(ProfileError, match=r"^huge\.eds: file is \d+ bytes"):
        import_eds(big, source="huge.eds")
    with pytest.raises(ProfileError, match="more than"):
        import_eds(GOOD.encode() + b";" * MAX_EDS_BYTES, source="huge.eds")


def test_latin1_bytes_are_read_and_utf8_bom_is_skipped() -> None:
    latin = GOOD.replace("VendorName=V", "VendorName=Müller °C").encode("latin-1")
    assert import_eds(latin, source="l.eds").identity.vendor_name == "Müller °C"
    assert import_eds(b"\xef\xbb\xbf" + GOOD.encode(), source="b.eds").identity.vendor_name == "V"
    windows = GOOD.replace("VendorName=V", "VendorName=\u201cM\u00fcller\u201d \u20ac").encode("cp1252")
    assert import_eds(windows, source="w.eds").identity.vendor_name == "\u201cM\u00fcller\u201d \u20ac"
    not_cp1252 = GOOD.replace("VendorName=V", "VendorName=\u00fc\x81").encode("latin-1")  # 0x81: no cp1252 char
    assert import_eds(not_cp1252, source="x.eds").identity.vendor_name == "\u00fc\x81"


# --- property: import(export(x)) == x ---------------------------------------------------------------------
@pytest.mark.slow  # measured 54-120 s of the quick subset on the loaded 2 cores
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(profiles())
def test_import_of_export_is_identity(profile: Profile) -> None:
    again = import_eds(export_eds(profile), source="whatever.eds")
    assert sorted(again.objects, key=lambda o: (o.index, o.subindex)) == sorted(
        profile.objects, key=lambda o: (o.index, o.subindex))
    assert again.model_dump(exclude={"objects", "features"}) == profile.model_dump(exclude={"objects", "features"})
    assert again.features.baud_rates_kbit == profile.features.baud_rates_kbit
    assert (again.features.rpdo_count, again.features.tpdo_count) == (
        profile.features.rpdo_count, profile.features.tpdo_count)


@st.composite
def _dcf_cases(draw: st.DrawFn) -> tuple[Profile, int, dict[tuple[int, int], int | float | str]]:
    profile = draw(profiles())
    chosen = draw(st.lists(st.sampled_from(profile.objects), unique_by=lambda o: (o.index, o.subindex), max_size=6))
    values = {(o.index, o.subindex): draw(raw_value(o.data_type, 1)) for o in chosen}
    return profile, draw(st.integers(1, 127)), values


@pytest.mark.slow  # measured 54-120 s of the quick subset on the loaded 2 cores
@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_dcf_cases())
def test_dcf_of_device_values_round_trips(case: tuple[Profile, int, dict[tuple[int, int], int | float | str]]
                                          ) -> None:
    """A DCF written with a device's (or a parameter set's) raw values for one node id reads back with those values
    as ParameterValue, every $NODEID formula resolved for that node, and the node id in [DeviceComissioning]."""
    profile, node_id, values = case
    again = import_eds(export_eds(profile, node_id=node_id, values=values, dcf=True, baud_kbit=250), source="n.dcf")
    assert again.extra_sections["DeviceComissioning"] == {"NodeID": str(node_id), "Baudrate": "250"}
    for before in profile.objects:
        after = obj(again, before.index, before.subindex)
        assert after.model_dump(exclude={"parameter_value"}) == before.model_dump(exclude={"parameter_value"})
        expected = values.get((before.index, before.subindex), before.parameter_value)
        if expected is None and before.default_expr is not None:
            expected = resolve_node_expr(before.default_expr, node_id)
        elif isinstance(expected, str) and before.data_type.is_integer:
            expected = resolve_node_expr(expected, node_id)
        assert after.parameter_value == expected, (hex(before.index), before.subindex)
