"""The regenerated XDD through the real API: an uploaded XDD written again keeps its PDO direction, features and
versions; an uploaded EDS as XDD names the keys CiA 311 has no place for (header and file) and an upload of that XDD
gives the EDS sections back."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from drivebench.device.formats.eds_ini import parse_ini
from tests.device.test_xdd_places import attributes, file_attributes, pdo_mapping, versions
from tests.device.xdd_quirk_corpus import ALL_FEATURES, EDS_SECTIONS, VERSIONED, xdd

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def upload(api: TestClient, name: str, content: bytes) -> str:
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    return str(response.json()["id"])


@pytest.mark.parametrize(("name", "content"), [("pdo.xdd", xdd()), ("features.xdd", ALL_FEATURES),
                                               ("versioned.xdd", VERSIONED)])
def test_a_regenerated_xdd_keeps_what_the_uploaded_one_said(api: TestClient, name: str, content: bytes) -> None:
    profile_id = upload(api, name, content)
    written = api.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    assert pdo_mapping(written) == pdo_mapping(content)
    for element in ("CANopenGeneralFeatures", "CANopenMasterFeatures"):
        assert {k: v for k, v in attributes(written, element).items() if k in attributes(content, element)} == \
            attributes(content, element)
    assert file_attributes(written) == file_attributes(content) and versions(written) == versions(content)


def test_an_eds_as_xdd_names_keys_without_a_place_and_comes_back_whole(api: TestClient) -> None:
    profile_id = upload(api, "servo.eds", EDS_SECTIONS.encode())
    response = api.get(f"/api/profiles/{profile_id}/xdd")
    warnings = json.loads(response.headers["X-DriveBench-Export-Warnings"])
    assert "[DeviceInfo] CompactPDO" in warnings and "[Tools] Tool1" in warnings
    assert not [w for w in warnings if "Granularity" in w or "Comments" in w or "DummyUsage" in w]
    again = upload(api, "servo-again.xdd", response.content)
    eds = api.get(f"/api/profiles/{again}/eds").text
    before, after = parse_ini(EDS_SECTIONS, "a.eds"), parse_ini(eds, "b.eds")
    for name in ("FILEINFO", "DUMMYUSAGE", "COMMENTS", "DEVICECOMISSIONING", "TOOLS"):
        assert {k.name: k.value for k in after[name].keys.values()} == \
            {k.name: k.value for k in before[name].keys.values()}, name
    device_info = {k.name: k.value for k in after["DEVICEINFO"].keys.values()}
    assert {k.name: device_info.get(k.name) for k in before["DEVICEINFO"].keys.values()} == \
        {k.name: k.value for k in before["DEVICEINFO"].keys.values()}
