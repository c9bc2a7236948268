"""Cases the outside corpus found (``benchmarks/outside_corpus.py``, issue 34), each through the real API with a
small file of its own making (``tests/device/lossless_corpus.py``)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from lxml import etree

from drivebench.device.formats.eds_ini import parse_ini
from tests.device.lossless_corpus import LOSSLESS_FILES
from tests.device.test_eds_rewrite import assert_only_key_changed

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def upload(api: TestClient, case_name: str) -> tuple[str, bytes]:
    name, content, _ = next(f for f in LOSSLESS_FILES if case_name in f[0])
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    return response.json()["id"], content


def through_xdd(api: TestClient, profile_id: str) -> tuple[bytes, dict[str, dict[str, str]]]:
    """The XDD export of a profile, and the [section] key=value of the EDS regenerated from it uploaded again."""
    xdd = api.get(f"/api/profiles/{profile_id}/xdd")
    assert xdd.status_code == 200, xdd.text
    again = api.post("/api/profiles", files={"file": (f"{profile_id}-again.xdd", xdd.content)})
    assert again.status_code == 201, again.text
    eds = api.get(f"/api/profiles/{again.json()['id']}/eds", params={"regenerate": "true"})
    assert eds.status_code == 200, eds.text
    return xdd.content, {name: {key: k.value for key, k in section.keys.items()}
                         for name, section in parse_ini(eds.content.decode(), "back.eds").items()}


def test_a_device_info_key_spelled_in_another_case_is_read_once_with_the_files_value(api: TestClient) -> None:
    """EMSISO's emDrive DCF writes ``SimpleBootupSlave=0``: read as ``SimpleBootUpSlave`` (CiA 306 key names are
    case-insensitive), not as an extra key next to the default 1 (an export with both was refused)."""
    profile_id, content = upload(api, "device-info-key-case")
    unedited = api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"})
    assert unedited.status_code == 200, unedited.text
    assert unedited.content == content
    xdd, back = through_xdd(api, profile_id)
    features = etree.fromstring(xdd).xpath("//*[local-name()='CANopenGeneralFeatures']")[0]
    assert features.get("bootUpSlave") in ("false", "0")
    assert back["DEVICEINFO"]["simplebootupslave"] == "0"


def test_an_empty_default_value_comes_back_through_an_xdd(api: TestClient) -> None:
    """Technosoft's ISD860 EDS writes ``DefaultValue=`` on 45 objects: no default, and the key kept through
    EDS -> XDD -> EDS (an empty ``defaultValue`` attribute)."""
    profile_id, content = upload(api, "empty-default-value")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    _, back = through_xdd(api, profile_id)
    assert back["1001"]["defaultvalue"] == "" and back["2001"]["defaultvalue"] == ""
    profile = api.get(f"/api/profiles/{profile_id}").json()
    assert next(o for o in profile["objects"] if o["index"] in ("0x1001", 0x1001))["default"] is None


def test_an_empty_comments_section_and_empty_identity_keys_come_back_through_an_xdd(api: TestClient) -> None:
    """``[Comments] Lines=0`` (python-canopen, CanFestival, Schunk ...), ``OrderCode=`` and ``VendorNumber=``
    (lely): nothing to hold, and the keys kept through EDS -> XDD -> EDS."""
    profile_id, content = upload(api, "empty-comments-and-identity-keys")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    profile = api.get(f"/api/profiles/{profile_id}").json()
    assert profile["notes"] == [] and profile["identity"]["vendor_id"] is None
    _, back = through_xdd(api, profile_id)
    assert back["COMMENTS"] == {"lines": "0"}
    assert back["DEVICEINFO"]["ordercode"] == "" and back["DEVICEINFO"]["vendornumber"] == ""


def test_a_sub_number_larger_than_the_sub_objects_listed_comes_back_through_an_xdd(api: TestClient) -> None:
    """EMSISO's partial DCF lists 2 of the 4 sub-objects of 0x1018 (``SubNumber=4``): the SubNumber is the file's
    in the XDD's ``subNumber`` and in the EDS written back from it."""
    profile_id, content = upload(api, "sub-number-larger-than-listed")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    xdd, back = through_xdd(api, profile_id)
    record = etree.fromstring(xdd).xpath("//*[local-name()='CANopenObject'][@index='2016']")[0]
    assert record.get("subNumber") == "4"
    assert back["2016"]["subnumber"] == "4" and "2016SUB3" in back


def test_objects_listed_off_their_index_range_stay_in_their_lists_through_an_xdd(api: TestClient) -> None:
    """The HEIG-VD canopen-stack lists 0x1017 as mandatory, lely-core lists manufacturer objects as optional: an XDD
    has no object lists, so the export says where each such object was listed and the EDS written back lists it
    there again."""
    profile_id, content = upload(api, "object-lists-off-their-range")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    _, back = through_xdd(api, profile_id)
    assert "0x1017" in back["MANDATORYOBJECTS"].values() and "0x1017" not in back["OPTIONALOBJECTS"].values()
    assert "0x2003" in back["OPTIONALOBJECTS"].values() and "0x2003" not in back["MANUFACTUREROBJECTS"].values()
    assert back["MANDATORYOBJECTS"]["supportedobjects"] == "4"


def test_a_sub_objects_object_type_and_an_array_without_sub_objects_come_back_through_an_xdd(
        api: TestClient) -> None:
    """HEIG-VD writes ``ObjectType=0x09`` on sub-objects; python-canopen's receiver.eds has an ARRAY section
    (0x3003) with neither sub-objects nor CompactSubObj: each comes back as written through EDS -> XDD -> EDS."""
    profile_id, content = upload(api, "sub-object-type-record")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    _, back = through_xdd(api, profile_id)
    assert int(back["2017SUB1"]["objecttype"], 0) == 9 and int(back["2017SUB0"]["objecttype"], 0) == 9
    profile_id, content = upload(api, "array-without-sub-objects")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    warnings = api.get(f"/api/profiles/{profile_id}").json().get("warnings", [])
    _, back = through_xdd(api, profile_id)
    assert int(back["2019"]["objecttype"], 0) == 8 and back["2019"]["datatype"] == "0x0008", (back.get("2019"),
                                                                                            warnings)
    assert back["2019"]["defaultvalue"] == ""


def test_iso_dates_and_an_empty_product_name_come_back_as_written_through_an_xdd(api: TestClient) -> None:
    """``CreationDate=2026-09-11`` (HEIG-VD; not the CiA 306 mm-dd-yyyy form) and ``ProductName=`` (lely-core's
    DCFs; the profile is named after the file, with a warning) are written back as the file had them."""
    profile_id, content = upload(api, "iso-dates")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    xdd, back = through_xdd(api, profile_id)
    body = etree.fromstring(xdd).xpath("//*[local-name()='ProfileBody']")[0]
    assert body.get("fileCreationDate") == "2024-01-15"
    assert (back["FILEINFO"]["creationdate"], back["FILEINFO"]["modificationdate"],
            back["FILEINFO"]["modificationtime"]) == ("2024-01-15", "2024-02-01", "14:05")
    profile_id, content = upload(api, "empty-product-name")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    assert api.get(f"/api/profiles/{profile_id}").json()["identity"]["product_name"]  # named after the file
    _, back = through_xdd(api, profile_id)
    assert back["DEVICEINFO"]["productname"] == ""


def test_compact_sub_obj_255_comes_back_as_written_through_an_xdd(api: TestClient) -> None:
    """python-canopen writes ``CompactSubObj=255`` on 0x1003: read as 254 sub-objects (sub-index 0xFF is no entry,
    CiA 301, with a warning), and the file's 255 written back as sub 0's default."""
    profile_id, content = upload(api, "compact-sub-obj-255")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    subs = [o for o in api.get(f"/api/profiles/{profile_id}").json()["objects"] if o["index"] in ("0x2018", 0x2018)]
    assert len(subs) == 255
    _, back = through_xdd(api, profile_id)
    assert back.get("2018", {}).get("compactsubobj", back.get("2018SUB0", {}).get("defaultvalue")) == "255"


def test_an_empty_file_info_key_comes_back_through_an_xdd(api: TestClient) -> None:
    """node-canopen's example.eds writes ``ModifiedBy=``: the XDD's ``fileModifiedBy=""`` is read back as the empty
    key, not dropped."""
    profile_id, content = upload(api, "empty-file-info-key")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    _, back = through_xdd(api, profile_id)
    assert back["FILEINFO"]["modifiedby"] == ""


def test_an_empty_parameter_name_comes_back_through_an_xdd(api: TestClient) -> None:
    """node-canopen's test.eds writes ``ParameterName=`` on 16 sub-objects: named ``Sub-index N`` (with a warning)
    and written back empty, also through EDS -> XDD -> EDS."""
    profile_id, content = upload(api, "empty-parameter-name")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    entry = next(o for o in api.get(f"/api/profiles/{profile_id}").json()["objects"]
                 if (o["index"], o["subindex"]) in (("0x2020", 1), (0x2020, 1)))
    assert entry["name"]
    _, back = through_xdd(api, profile_id)
    assert back["2020SUB1"]["parametername"] == ""
    renamed = api.patch(f"/api/profiles/{profile_id}/objects/0x2020/1", json={"name": "Slot 1"})
    assert renamed.status_code == 200, renamed.text
    assert_only_key_changed(content, api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content,
                            "empty.eds", "2020sub1", "ParameterName")


def test_an_unusable_factor_and_an_empty_description_come_back_through_an_xdd(api: TestClient) -> None:
    """python-canopen's sample.eds (test/sample.eds of the canopen releases 2.2.0 to 2.4.1 on PyPI) writes
    ``Factor=ERROR``, ``Description=`` and ``Unit=`` on 0x3050 sub 2: the factor is read as 1 with a warning and all
    three are written back as they were, also through EDS -> XDD -> EDS (they were lost there)."""
    profile_id, content = upload(api, "unusable-factor-empty-description")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    entry = next(o for o in api.get(f"/api/profiles/{profile_id}").json()["objects"]
                 if (o["index"], o["subindex"]) in (("0x2001", 0), (0x2001, 0)))
    assert entry.get("factor", 1) == 1
    _, back = through_xdd(api, profile_id)
    assert back["2001"]["factor"] == "ERROR"
    assert back["2001"]["description"] == "" and back["2001"]["unit"] == ""
    assert back["2002"]["factor"] == "1"  # a factor of 1, written out: no model field holds it either


def test_an_object_listed_without_a_section_stays_listed_through_an_xdd(api: TestClient) -> None:
    """python-canopen's examples/eds/e35.eds (canopen 1.2.1 to 2.4.1 on PyPI) and gocanopen's test_zipped_format.eds
    list an object that has no section (0x6505 in [OptionalObjects]): no object is read (warned) and the listing is
    kept (``extra_sections``), through the XDD as an ``EDS:[OptionalObjects]0x6505`` property, so the EDS written
    back lists it again (it was lost there)."""
    profile_id, content = upload(api, "listed-without-section")
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
    profile = api.get(f"/api/profiles/{profile_id}").json()
    assert not [o for o in profile["objects"] if o["index"] in ("0x6505", 0x6505)]
    _, back = through_xdd(api, profile_id)
    listed = {int(v, 16) for k, v in back["OPTIONALOBJECTS"].items() if k.isdigit()}
    assert 0x6505 in listed and {0x1008, 0x1400, 0x1800, 0x6040} <= listed
    assert int(back["OPTIONALOBJECTS"]["supportedobjects"]) == len(listed)
    assert "6505" not in back
