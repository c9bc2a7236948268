"""``GET /api/profiles/{id}/eds`` serves exactly the EDS file shipped in ``device_profiles/eds/``."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.device.formats.build_eds import eds_path, shipped_profiles
from drivebench.web.app import create_app

SHIPPED = [profile.id for profile in shipped_profiles()]


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The app without a plant; uploads (none here) would go to a temporary directory."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", tmp_path_factory.mktemp("user-profiles"))
        with TestClient(create_app()) as client:
            yield client


@pytest.mark.parametrize("profile_id", SHIPPED)
def test_eds_endpoint_serves_the_shipped_file(api: TestClient, profile_id: str) -> None:
    response = api.get(f"/api/profiles/{profile_id}/eds")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain")
    assert response.headers["content-disposition"] == f'attachment; filename="{profile_id}.eds"'
    shipped = eds_path(next(p for p in shipped_profiles() if p.id == profile_id))
    assert response.text == Path(shipped).read_text(encoding="utf-8")


def test_eds_of_an_unknown_profile_is_a_problem(api: TestClient) -> None:
    response = api.get("/api/profiles/no-such-drive/eds")
    assert response.status_code == 404
    assert response.headers["content-type"].startswith("application/problem+json")
    assert "no-such-drive" in response.json()["detail"]
