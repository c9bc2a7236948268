"""Stored uploads are parsed once (issue 33): a restart takes them from the parsed cache beside the upload folder
(``<folder>.parsed/``) and they are listed, searched, downloaded and given to nodes as before; an entry serves only
the very bytes it was made from."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app
from tests.conftest import fresh_channel

SERVO_EDS = REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds"


@contextmanager
def server(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    """A start of the server on ``user_dir`` (each ``with`` is a restart)."""
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        yield client


def parsed_entries(user_dir: Path) -> list[Path]:
    return sorted(user_dir.with_name(user_dir.name + ".parsed").glob("*.json"))


def what_it_offers(client: TestClient, profile_id: str) -> dict[str, object]:
    return {"summary": next(p for p in client.get("/api/profiles").json() if p["id"] == profile_id),
            "search": client.get(f"/api/profiles/{profile_id}/parameters", params={"q": "0x6040"}).json(),
            "warnings": client.get(f"/api/profiles/{profile_id}/warnings").json(),
            "eds": client.get(f"/api/profiles/{profile_id}/eds").content,
            "profile": client.get(f"/api/profiles/{profile_id}").json()}


def test_an_upload_taken_from_the_parsed_cache_is_listed_searchable_and_usable(
        user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with server(user_dir, monkeypatch) as client:
        profile_id = client.post("/api/profiles", files={"file": (SERVO_EDS.name, SERVO_EDS.read_bytes())}).json()["id"]
    with server(user_dir, monkeypatch) as client:  # parses the stored file, keeps what it made of it
        parsed = what_it_offers(client, profile_id)
    assert len(parsed_entries(user_dir)) == 1
    with server(user_dir, monkeypatch) as client:  # takes it from the cache
        cached = what_it_offers(client, profile_id)
        assert cached == parsed
        assert cached["search"]["items"][0]["name"] == "Controlword"  # type: ignore[index]
        assert cached["warnings"] and cached["eds"] == (user_dir / f"{profile_id}.eds").read_bytes()
        session = client.post("/api/sessions", json={"bus": f"virtual:{fresh_channel()}@500000"}).json()["id"]
        node = client.post(f"/api/sessions/{session}/nodes", json={"node_id": 9, "profile_id": profile_id})
        assert node.status_code == 201 and node.json()["profile_id"] == profile_id
        rows = client.get(f"/api/sessions/{session}/nodes/9/parameters", params={"q": "0x6040"})
        assert rows.status_code == 200 and "Controlword" in rows.text
        client.delete(f"/api/sessions/{session}")


def test_an_entry_serves_only_the_bytes_it_was_made_from(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with server(user_dir, monkeypatch) as client:
        profile_id = client.post("/api/profiles", files={"file": (SERVO_EDS.name, SERVO_EDS.read_bytes())}).json()["id"]
    with server(user_dir, monkeypatch):
        pass
    [entry] = parsed_entries(user_dir)
    kept = entry.read_text(encoding="utf-8")
    assert kept.count('"product_name":"EM-Servo 400"') == 1
    entry.write_text(kept.replace('"product_name":"EM-Servo 400"', '"product_name":"Read from the cache"'),
                     encoding="utf-8")
    with server(user_dir, monkeypatch) as client:  # the same bytes: the entry is what the start reads
        assert client.get(f"/api/profiles/{profile_id}").json()["identity"]["product_name"] == "Read from the cache"

    stored = user_dir / f"{profile_id}.eds"
    stored.write_bytes(stored.read_bytes() + b"\r\n; changed on disk\r\n")
    with server(user_dir, monkeypatch) as client:  # other bytes: parsed again, the old entry dropped
        assert client.get(f"/api/profiles/{profile_id}").json()["identity"]["product_name"] == "EM-Servo 400"
    [renewed] = parsed_entries(user_dir)
    assert renewed != entry

    renewed.write_text("{not json", encoding="utf-8")
    with server(user_dir, monkeypatch) as client:  # an entry that does not read: parsed again
        assert client.get(f"/api/profiles/{profile_id}").json()["identity"]["product_name"] == "EM-Servo 400"
