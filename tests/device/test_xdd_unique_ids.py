"""An XDD written again names its parameters as the uploaded one did (``uniqueID`` and each object's
``uniqueIDRef``), so XDD -> XDD keeps the file's references."""

from __future__ import annotations

from lxml import etree

from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_xdd
from tests.device.xdd_quirk_corpus import UNIQUE_IDS

NS = "{http://www.canopen.org/xml/1.0}"


def references(content: bytes) -> dict[str, str]:
    """index[/subIndex] -> uniqueIDRef of each object and sub-object 0x2000.. that has one."""
    found = {}
    for obj in etree.fromstring(content).iter(f"{NS}CANopenObject"):
        if str(obj.get("index")) < "2000":
            continue
        if obj.get("uniqueIDRef"):
            found[str(obj.get("index"))] = str(obj.get("uniqueIDRef"))
        for sub in obj.iter(f"{NS}CANopenSubObject"):
            if sub.get("uniqueIDRef"):
                found[f"{obj.get('index')}/{sub.get('subIndex')}"] = str(sub.get("uniqueIDRef"))
    return found


def parameter_ids(content: bytes) -> set[str]:
    return {str(p.get("uniqueID")) for p in etree.fromstring(content).iter(f"{NS}parameter")}


def test_parameter_unique_ids_go_through_xdd_to_xdd() -> None:
    written = export_xdd(read_xdd(UNIQUE_IDS, source="in.xdd").profile)
    assert references(written) == references(UNIQUE_IDS) == {
        "2000": "UID_Speed", "2100": "UID_REC_2100", "2100/01": "UID_SUB_210001"}
    assert parameter_ids(written) >= {"UID_Speed", "UID_REC_2100", "UID_SUB_210001"}


def test_unique_ids_are_kept_through_a_second_round() -> None:
    once = export_xdd(read_xdd(UNIQUE_IDS, source="in.xdd").profile)
    assert references(export_xdd(read_xdd(once, source="once.xdd").profile)) == references(once)
