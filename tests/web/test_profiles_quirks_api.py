"""Quirky device descriptions through the real API: accepted with warnings[], the warnings stored with the profile
(also after a restart), the file downloads back byte for byte, and a refused file changes nothing."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.web.app import create_app
from tests.device.quirk_corpus import CORPUS_FILES

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    return tmp_path / "user-profiles"


@pytest.fixture
def api(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        yield client


def test_every_corpus_file_uploads_with_its_warnings_and_downloads_byte_identical(api: TestClient,
                                                                                   user_dir: Path) -> None:
    for name, content, case in CORPUS_FILES:
        response = api.post("/api/profiles", files={"file": (name, content)})
        assert response.status_code == 201, (name, response.text)
        body = response.json()
        messages = [w["message"] for w in body["warnings"]]
        assert body["warning_count"] == len(messages)
        if case.warns is None:
            assert messages == [], name
        else:
            assert any(case.warns in m for m in messages), (name, messages)
            assert all(w["file"] == name for w in body["warnings"])
        download = api.get(f"/api/profiles/{body['id']}/eds")
        assert download.status_code == 200 and download.content == content, name
        assert download.headers["content-disposition"].endswith(f'{case.suffix}"')
        assert api.get(f"/api/profiles/{body['id']}/warnings").json() == body["warnings"]
    listed = {p["id"]: p["warning_count"] for p in api.get("/api/profiles").json()}
    assert sum(1 for _, _, case in CORPUS_FILES if case.warns) <= sum(1 for n in listed.values() if n)


def test_warnings_survive_a_restart_and_limit_notes_reach_the_rows(user_dir: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    name, content, _ = next(f for f in CORPUS_FILES if "signed-limits-on-unsigned32" in f[0])
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        profile_id = client.post("/api/profiles", files={"file": (name, content)}).json()["id"]
    with TestClient(create_app()) as client:  # read again from the upload folder
        warnings = client.get(f"/api/profiles/{profile_id}/warnings").json()
        assert [w["object"] for w in warnings if w["limits"]] == ["0x2000sub0"]
        row = client.get(f"/api/profiles/{profile_id}/parameters", params={"q": "0x2000"}).json()["items"][0]
        assert row["min"] is None and row["max"] is None
        assert "limits dropped: LowLimit 0x80000000 > HighLimit 0x7FFFFFFF" in row["limits_note"]
        regenerated = client.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"})
        assert regenerated.content != content and b"[2000]" in regenerated.content


def test_a_file_without_object_dictionary_is_refused_and_nothing_is_lost(api: TestClient) -> None:
    name, content, _ = CORPUS_FILES[0]
    kept = api.post("/api/profiles", files={"file": (name, content)}).json()["id"]
    before = api.get("/api/profiles").json()
    for junk in (b"\x00\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, b"", b"[FileInfo]\nFileName=x.eds\n",
                 content[:300]):
        refused = api.post("/api/profiles", files={"file": ("junk.eds", junk)})
        assert refused.status_code == 422, refused.text
        assert refused.headers["content-type"].startswith("application/problem+json")
        assert refused.json()["source"] == "junk.eds" and "object" in refused.json()["detail"]
    assert api.get("/api/profiles").json() == before
    assert api.get(f"/api/profiles/{kept}/eds").content == content


XDD_DIR = Path(__file__).resolve().parents[1] / "data" / "xdd"


@pytest.mark.parametrize("name", sorted(p.name for p in XDD_DIR.iterdir()))
def test_xdd_and_xdc_upload_and_download_byte_identical(api: TestClient, name: str) -> None:
    content = (XDD_DIR / name).read_bytes()
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    profile_id = response.json()["id"]
    original = api.get(f"/api/profiles/{profile_id}/xdd")
    assert original.content == content and original.headers["content-type"].startswith("application/xml")
    written = api.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    again = api.post("/api/profiles", files={"file": ("again.xdd", written)})
    # the export adds the CiA 301 mandatory objects a file lacks (quirks.xdd has no 0x1001, 0x1018)
    assert again.status_code == 201 and again.json()["objects"] >= response.json()["objects"]
    as_eds = api.get(f"/api/profiles/{profile_id}/eds").content
    again_eds = api.post("/api/profiles", files={"file": ("again.eds", as_eds)})
    assert again_eds.status_code == 201 and again_eds.json()["objects"] == again.json()["objects"]


def test_unsafe_xml_upload_is_a_problem_in_words(api: TestClient) -> None:
    before = api.get("/api/profiles").json()
    xxe = b'<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n<x>&e;</x>'
    refused = api.post("/api/profiles", files={"file": ("evil.xdd", xxe)})
    assert refused.status_code == 422
    assert (refused.json()["source"], refused.json()["line"]) == ("evil.xdd", 2)
    assert "DOCTYPE" in refused.json()["detail"] and "passwd" not in refused.text.replace("file:///etc/passwd", "")
    assert api.get("/api/profiles").json() == before
