"""An uploaded EDS edited through the API: the regenerated export differs from the upload only in the edited key,
an unedited one not at all; edits that do not fit are refused in words and change nothing (issue 34)."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from tests.device.lossless_corpus import LOSSLESS_FILES
from tests.device.test_eds_rewrite import assert_only_key_changed


def upload(api: TestClient, case_name: str) -> tuple[str, str, bytes]:
    name, content, _ = next(f for f in LOSSLESS_FILES if case_name in f[0])
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    return response.json()["id"], name, content


@pytest.mark.parametrize("case_name", ["comments-blank-lines-inline", "cp1252-crlf", "hex-style-lower-case",
                                       "object-obj-flags", "domain-values-dcf"])
def test_an_edit_through_the_api_changes_only_its_key_in_the_regenerated_export(api: TestClient,
                                                                                 case_name: str) -> None:
    profile_id, name, content = upload(api, case_name)
    unedited = api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"})
    assert unedited.status_code == 200 and unedited.content == content
    case = next(c for n, _, c in LOSSLESS_FILES if n == name)
    index, sub = case.edit.address
    response = api.patch(f"/api/profiles/{profile_id}/objects/0x{index:04X}/{sub}",
                         json={case.edit.field: case.edit.value})
    assert response.status_code == 200, response.text
    assert next(o for o in response.json()["objects"] if (int(o["index"], 16), o["subindex"]) == (index, sub))[
        case.edit.field] == case.edit.value
    regenerated = api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content
    assert_only_key_changed(content, regenerated, name, case.edit.section, case.edit.key)
    assert api.get(f"/api/profiles/{profile_id}/eds").content == regenerated  # the stored file is the edited one


def test_an_edit_that_does_not_fit_is_refused_in_words_and_changes_nothing(api: TestClient,
                                                                          user_dir: Path) -> None:
    profile_id, _, content = upload(api, "comments-blank-lines-inline")
    for url, body, status in ((f"/api/profiles/{profile_id}/objects/0x2000/0", {"default": "fast"}, 422),
                              (f"/api/profiles/{profile_id}/objects/0x2FFF/0", {"default": 1}, 404),
                              (f"/api/profiles/{profile_id}/objects/zz/0", {"default": 1}, 404),
                              (f"/api/profiles/{profile_id}/objects/0x2000/0", {"colour": 1}, 422),
                              ("/api/profiles/generic-cia402-servo/objects/0x6040/0", {"default": 1}, 409)):
        refused = api.patch(url, json=body)
        assert refused.status_code == status, refused.text
        assert refused.headers["content-type"].startswith("application/problem+json")
        assert refused.json()["detail"]
    assert api.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content == content
