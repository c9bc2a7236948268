"""An uploaded XDD edited through the API (issue 34): the regenerated XDD is the upload, byte for byte, while nobody
edited it; after a PATCH it differs from the upload only in the edited value, written where the file holds it (an
object attribute, or the parameter's ``defaultValue`` element of the object dictionary editors' layout)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.device.xdd_rewrite_corpus import ATTRIBUTES, PARAMETERS
from tests.device.xml_trees import tree_changes


@pytest.mark.parametrize(("name", "content", "place"), [
    ("attributes.xdd", ATTRIBUTES, ("CANopenObject[index=2000]", "@defaultValue")),
    ("parameters.xdd", PARAMETERS, ("{http://www.canopen.org/xml/1.1}defaultValue[1]", "@value"))])
def test_an_xdd_edit_through_the_api_changes_only_that_value_in_the_regenerated_xdd(
        api: TestClient, name: str, content: bytes, place: tuple[str, str]) -> None:
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    profile_id = response.json()["id"]
    unedited = api.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"})
    assert unedited.status_code == 200 and unedited.content == content
    patched = api.patch(f"/api/profiles/{profile_id}/objects/0x2000/0", json={"default": 3500})
    assert patched.status_code == 200, patched.text
    assert next(o for o in patched.json()["objects"] if o["index"] in ("0x2000", "2000", 0x2000))["default"] == 3500
    regenerated = api.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    gone, added = tree_changes(content, regenerated)
    assert [(path.endswith(place[0]), attribute, value) for path, attribute, value in gone] == [
        (True, place[1], "0x0BB8")]
    assert [(path.endswith(place[0]), attribute, value) for path, attribute, value in added] == [
        (True, place[1], "0x0DAC")]
    assert api.get(f"/api/profiles/{profile_id}/xdd").content == regenerated  # the stored file is the edited one
    refused = api.patch(f"/api/profiles/{profile_id}/objects/0x2000/0", json={"default": "fast"})
    assert refused.status_code == 422 and refused.json()["detail"]
    assert api.get(f"/api/profiles/{profile_id}/xdd").content == regenerated  # a refused edit changes nothing


def test_the_profile_page_of_an_xdd_upload_points_to_download_xdd_for_the_edited_file(api: TestClient) -> None:
    """The edit form's hint named "Download EDS" for an XDD upload too, whose edits are in Download XDD."""
    assert api.post("/api/profiles", files={"file": ("attributes.xdd", ATTRIBUTES)}).status_code == 201
    page = api.get("/profiles/attributes?q=2000")
    assert page.status_code == 200, page.text
    assert "Download XDD shows it" in page.text and "Download EDS shows it" not in page.text
