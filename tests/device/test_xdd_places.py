"""What CiA 311 says beyond the object list goes through DriveBench: XDD -> profile -> XDD keeps the PDO direction,
the NMT/LSS features, the file attributes and the version elements; EDS -> XDD -> EDS keeps every section an XDD has
a place for, and the export's warnings name the EDS keys that have none (kept as ``EDS:`` properties)."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from drivebench.device.formats.eds import read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.eds_ini import parse_ini
from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_warnings, export_xdd
from drivebench.device.formats.xdd_places import GENERAL_FEATURES, MASTER_FEATURES, NUMBER_FEATURES
from tests.device.xdd_quirk_corpus import ALL_FEATURES, EDS_SECTIONS, PDO_KINDS, TOOL_PROPERTIES, VERSIONED, xdd

NS = "{http://www.canopen.org/xml/1.0}"
KEPT_SECTIONS = ("FileInfo", "DummyUsage", "Comments", "DeviceComissioning", "Tools")


def through_xdd(content: bytes) -> bytes:
    return export_xdd(read_xdd(content, source="in.xdd").profile)


def pdo_mapping(content: bytes) -> dict[str, str]:
    """PDOmapping of the objects 0x2000... (the export adds the CiA 301 mandatory objects a file lacks)."""
    root = etree.fromstring(content)
    return {str(o.get("index")): str(o.get("PDOmapping")) for o in root.iter(f"{NS}CANopenObject")
            if str(o.get("index")) >= "2000"}


def attributes(content: bytes, element: str) -> dict[str, str]:
    """The attributes of the first ``element``, xsd:boolean written one way (``TRUE`` and ``1`` are ``true``)."""
    found = next(etree.fromstring(content).iter(f"{NS}{element}"))
    return {str(k): ({"1": "true", "0": "false"}.get(str(v).lower(), str(v).lower())
                     if k not in NUMBER_FEATURES and v.lower() in ("true", "false", "1", "0") else str(v))
            for k, v in found.attrib.items() if "}" not in str(k)}


def file_attributes(content: bytes) -> list[dict[str, str]]:
    return [{str(k): str(v) for k, v in body.attrib.items() if str(k).startswith("file")}
            for body in etree.fromstring(content).iter(f"{NS}ProfileBody")]


def versions(content: bytes) -> list[tuple[str, str]]:
    return [(str(v.get("versionType")), (v.text or "").strip()) for v in etree.fromstring(content).iter(f"{NS}version")]


def sections(text: str) -> dict[str, dict[str, str]]:
    return {s.name: {k.name: k.value for k in s.keys.values()} for s in parse_ini(text, "x.eds").values()}


def test_a_tools_own_parameter_properties_go_through_xdd_to_xdd() -> None:
    """CANopenNode's demoDevice.xdd has 30 ``CO_*`` properties on its parameters: an XDD written again has each on
    its object's parameter, as read."""
    def properties(content: bytes) -> set[tuple[str, str, str]]:
        """(index of the object whose parameter has it, name, value) of each CO_ property."""
        root = etree.fromstring(content)
        owner = {str(o.get("uniqueIDRef")): str(o.get("index")) for o in root.iter(f"{NS}CANopenObject")}
        return {(owner.get(str(p.getparent().get("uniqueID")), "?"), str(p.get("name")), str(p.get("value")))
                for p in root.iter(f"{NS}property") if str(p.get("name")).startswith("CO_")}

    assert properties(through_xdd(TOOL_PROPERTIES)) == properties(TOOL_PROPERTIES) == {
        ("2000", "CO_storageGroup", "PERSIST_COMM"), ("2000", "CO_countLabel", "VAL")}


def test_the_pdo_direction_goes_through_xdd_to_xdd() -> None:
    content = xdd()
    profile = read_xdd(content, source="pdo.xdd").profile
    assert [o.pdo_mapping_kind for o in profile.objects if o.index >= 0x2000] == ["TPDO", "RPDO", "default", None,
                                                                                 None]
    assert pdo_mapping(through_xdd(content)) == pdo_mapping(content)


def test_nmt_and_lss_features_go_through_xdd_to_xdd() -> None:
    again = through_xdd(ALL_FEATURES)
    for element in ("CANopenGeneralFeatures", "CANopenMasterFeatures"):
        assert attributes(again, element) == attributes(ALL_FEATURES, element)
    info = read_xdd(ALL_FEATURES, source="f.xdd").profile.extra_sections["DeviceInfo"]
    assert (info["Granularity"], info["LSS_Supported"], info["SimpleBootUpSlave"], info["LSS_Master"]) == (
        "0", "1", "0", "1")


def test_file_attributes_and_version_elements_go_through_xdd_to_xdd() -> None:
    again = through_xdd(VERSIONED)
    assert file_attributes(again) == file_attributes(VERSIONED)
    assert versions(again) == versions(VERSIONED)
    file_info = read_xdd(VERSIONED, source="v.xdd").profile.extra_sections["FileInfo"]
    assert (file_info["CreationDate"], file_info["ModificationTime"]) == ("06-30-2021", "08:00AM")  # the EDS form


def test_a_file_attribute_only_the_device_body_has_is_read() -> None:
    """CANopenNode's demoDevice.xdd (CANopenEditor) writes ``fileModifiedBy`` on the device profile's body only: it
    is the [FileInfo] ModifiedBy all the same (the communication body's attributes first where both have one)."""
    content = xdd(file={"fileName": "io.xdd", "fileCreator": "Editor", "fileVersion": "1"},
                  device_file={"fileName": "io.xdd", "fileCreator": "Other", "fileModifiedBy": "J. Doe",
                               "fileVersion": "1"})
    file_info = read_xdd(content, source="io.xdd").profile.extra_sections["FileInfo"]
    assert (file_info["ModifiedBy"], file_info["CreatedBy"]) == ("J. Doe", "Editor")


def test_eds_sections_go_through_xdd_back_to_eds_and_the_warnings_name_keys_without_a_place() -> None:
    profile = read_eds(EDS_SECTIONS, source="servo.eds").profile
    written = export_xdd(profile)
    back = read_xdd(written, source="servo.xdd").profile
    assert back.notes == ["First comment line", "Second, with (more) words"]
    before, after = sections(EDS_SECTIONS), sections(export_eds(back))
    for name in KEPT_SECTIONS:
        assert after[name] == before[name], name
    assert {k: after["DeviceInfo"][k] for k in before["DeviceInfo"]} == before["DeviceInfo"]
    assert after["DeviceInfo"]["Granularity"] == "0"
    assert 'granularity="0"' in written.decode() and 'layerSettingServiceSlave="true"' in written.decode()
    warnings = export_warnings(profile)
    assert {"[DeviceInfo] CompactPDO", "[DeviceInfo] LSS_Type", "[DeviceComissioning] LSS_SerialNumber",
            "[Tools] Items", "[FileInfo] FileRevision"} <= set(warnings)
    assert not [w for w in warnings if "Granularity" in w or "LSS_Supported" in w or "Dummy" in w]
    assert "[DeviceInfo] CompactPDO" in written.decode().split("<ISO15745Profile>")[0]  # the file says it too


_BOOL = st.sampled_from(["true", "false"])


@st.composite
def _features(draw: st.DrawFn, names: dict[str, str]) -> dict[str, str]:
    chosen = draw(st.lists(st.sampled_from(sorted(names)), unique=True))
    return {name: str(draw(st.integers(0, 255))) if name in NUMBER_FEATURES else draw(_BOOL) for name in chosen}


_TEXT = st.from_regex(r"[A-Za-z0-9][A-Za-z0-9 .,()_-]{0,20}[A-Za-z0-9]", fullmatch=True)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pdo=st.lists(st.sampled_from(PDO_KINDS), min_size=1, max_size=6), general=_features(GENERAL_FEATURES),
       master=_features(MASTER_FEATURES),
       file=st.fixed_dictionaries({"fileName": _TEXT, "fileCreator": _TEXT, "fileVersion": _TEXT},
                                  optional={"fileCreationDate": st.dates().map(str), "fileModifiedBy": _TEXT,
                                            "fileCreationTime": st.times().map(lambda t: t.strftime("%H:%M:%S"))}),
       kept_versions=st.lists(st.tuples(st.sampled_from(["FW", "HW", "SW"]), _TEXT), max_size=4))
def test_xdd_to_xdd_keeps_pdo_direction_features_and_versions(pdo: list[str], general: dict[str, str],
                                                               master: dict[str, str], file: dict[str, str],
                                                               kept_versions: list[tuple[str, str]]) -> None:
    content = xdd(pdo=pdo, general=general, master=master, file=file, versions=kept_versions)
    again = through_xdd(content)
    assert pdo_mapping(again) == pdo_mapping(content)
    for element, given_attributes in (("CANopenGeneralFeatures", general), ("CANopenMasterFeatures", master)):
        written = attributes(again, element)
        assert {k: written[k] for k in given_attributes} == {k: attributes(content, element)[k]
                                                            for k in given_attributes}
    assert [{k: v for k, v in body.items() if k in file} for body in file_attributes(again)] == [file, file]
    assert versions(again) == kept_versions or (not kept_versions and versions(again) == [])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(granularity=st.integers(0, 64), lss=st.sampled_from(["0", "1"]), compact=st.sampled_from(["0", "0x3F", "1"]),
       dummies=st.lists(st.sampled_from(["0", "1"]), min_size=1, max_size=7), comments=st.lists(_TEXT, max_size=4),
       node=st.integers(1, 127), node_name=_TEXT)
def test_eds_to_xdd_to_eds_keeps_the_sections_xdd_has_a_place_for(granularity: int, lss: str, compact: str,
                                                                   dummies: list[str], comments: list[str],
                                                                   node: int, node_name: str) -> None:
    text = (EDS_SECTIONS.replace("Granularity=0", f"Granularity={granularity}")
            .replace("LSS_Supported=1", f"LSS_Supported={lss}").replace("CompactPDO=0x3F", f"CompactPDO={compact}")
            .replace("Dummy0001=0\nDummy0002=1", "\n".join(f"Dummy{n:04X}={v}" for n, v in enumerate(dummies, 1)))
            .replace("Lines=2\nLine1=First comment line\nLine2=Second, with (more) words",
                     "\n".join([f"Lines={len(comments)}", *(f"Line{n}={c}" for n, c in enumerate(comments, 1))]))
            .replace("NodeID=5\nNodeName=Left axis", f"NodeID={node}\nNodeName={node_name}"))
    profile = read_eds(text, source="servo.eds").profile
    back = read_xdd(export_xdd(profile), source="servo.xdd").profile
    assert back.extra_sections == profile.extra_sections and back.notes == profile.notes
    before, after = sections(text), sections(export_eds(back))
    for name in ("DummyUsage", "DeviceComissioning", "Tools"):
        assert after[name] == before[name]
    for key in ("Granularity", "LSS_Supported", "CompactPDO"):
        assert after["DeviceInfo"][key] == before["DeviceInfo"][key]
