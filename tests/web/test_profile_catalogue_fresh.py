"""An upload that replaces a profile (same id, new content) is searched in its new content: the profile's catalogue
is built for the new profile object, not served from the one before (issue 29, one catalogue cache)."""

from __future__ import annotations

from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT

SERVO_EDS = REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds"


def test_a_replaced_profile_is_searched_in_its_new_content(api: TestClient) -> None:
    first = api.post("/api/profiles", files={"file": (SERVO_EDS.name, SERVO_EDS.read_bytes())})
    assert first.status_code == 201, first.text
    profile_id = first.json()["id"]
    search = f"/api/profiles/{profile_id}/parameters"
    assert api.get(search, params={"q": "0x6040"}).json()["items"][0]["name"] == "Controlword"

    renamed = SERVO_EDS.read_bytes().replace(b"ParameterName=Controlword", b"ParameterName=Steuerwort neu")
    second = api.post("/api/profiles", files={"file": (SERVO_EDS.name, renamed)})
    assert second.status_code == 201, second.text
    assert second.json()["id"] == profile_id

    assert api.get(search, params={"q": "0x6040"}).json()["items"][0]["name"] == "Steuerwort neu"
    assert api.get(search, params={"q": "Steuerwort"}).json()["total"] >= 1
    assert all(row["name"] != "Controlword" for row in api.get(search, params={"q": "Controlword"}).json()["items"])
    page = api.get(f"/profiles/{profile_id}", params={"q": "0x6040"})
    assert page.status_code == 200 and "Steuerwort neu" in page.text
