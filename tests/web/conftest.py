"""Fixtures of the web tests: the app without a plant whose profile uploads go to a temporary directory."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    return tmp_path / "user-profiles"


@pytest.fixture
def api(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    """The app without a plant; its registry stores uploads in ``user_dir``."""
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        yield client


@pytest.fixture
def demo_server() -> Iterator[tuple[str, Plant]]:
    """The demo plant on a fresh virtual bus, served by uvicorn: the base URL and the simulated plant."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as base_url:
        plants: dict[str, Plant] = app.state.drivebench.plants
        yield base_url, next(iter(plants.values()))


@contextlib.contextmanager
def demo_server_with_own_db(tmp_path_factory: pytest.TempPathFactory, name: str) -> Iterator[str]:
    """The demo plant served by uvicorn with a SQLite database of its own (a module's stored sets stay out of var/)."""
    url = f"sqlite:///{tmp_path_factory.mktemp(name) / 'drivebench.db'}"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", url)
        app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
        with serve_app(app) as base_url:
            yield base_url
    database.dispose(url)
