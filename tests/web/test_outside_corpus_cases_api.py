"""Cases the outside corpus found (``benchmarks/outside_corpus.py``, issue 34), each through the real API with a
small file of its own making (``tests/device/lossless_corpus.py``)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from lxml import etree

from drivebench.device.formats.eds_ini import parse_ini
from tests.device.lossless_corpus import LOSSLESS_FILES

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
