"""What a CiA 311 ProfileBody holds beside the object list (``formatName``, ``formatVersion``,
``supportedLanguages``, the DeviceFunction characteristics, empty ``vendorID``/``productID`` elements) goes through
XDD -> XDD, and through XDD -> EDS -> XDD."""

from __future__ import annotations

from lxml import etree

from drivebench.device.formats.eds import read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_warnings, export_xdd
from tests.device.xdd_quirk_corpus import HEADER_PLACES

NS = "{http://www.canopen.org/xml/1.0}"
BODY_ATTRIBUTES = ("formatName", "formatVersion", "supportedLanguages")


def header_places(content: bytes) -> dict[str, object]:
    root = etree.fromstring(content)
    bodies = list(root.iter(f"{NS}ProfileBody"))
    identity = next(root.iter(f"{NS}DeviceIdentity"))
    characteristics = [[(etree.QName(e).localname, str(e.text).strip()) for e in c.iter() if (e.text or "").strip()]
                       for c in root.iter(f"{NS}characteristic")]
    return {"bodies": [{a: b.get(a) for a in BODY_ATTRIBUTES} for b in bodies],
            "identity": [(etree.QName(e).localname, (e.text or "").strip()) for e in identity
                         if etree.QName(e).localname in ("vendorID", "productID")],
            "characteristics": characteristics}


def test_header_places_go_through_xdd_to_xdd() -> None:
    written = export_xdd(read_xdd(HEADER_PLACES, source="in.xdd").profile)
    assert header_places(written) == header_places(HEADER_PLACES)
    assert header_places(written)["characteristics"] == [
        [("label", "Stack"), ("label", "Stack 4.0"), ("label", "CiA 301 4.2")]]
    assert header_places(written)["identity"] == [("vendorID", ""), ("productID", "")]


def test_header_places_go_through_xdd_to_eds_to_xdd() -> None:
    profile = read_xdd(HEADER_PLACES, source="in.xdd").profile
    eds = export_eds(profile)
    again = export_xdd(read_eds(eds.encode(), source="in.eds").profile)
    assert header_places(again) == header_places(HEADER_PLACES)
    assert export_warnings(profile) == []
