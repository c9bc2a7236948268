"""Fixtures of the web tests: the app without a plant whose profile uploads go to a temporary directory."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.web.app import create_app


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    return tmp_path / "user-profiles"


@pytest.fixture
def api(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    """The app without a plant; its registry stores uploads in ``user_dir``."""
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        yield client
