"""Stored uploads load after the server listens (issue 33): ``/api/health`` answers while a worker thread still
reads them (``profiles.state`` ``loading``), lists show what is loaded with a line saying how far it is, a node
given a stored upload waits for it, and a broken upload is reported as at any start.

Many cold uploads (no parsed cache yet: each EDS is parsed) make the loading take seconds on any machine."""

from __future__ import annotations

import gc
import json
import re
import time
from pathlib import Path

import httpx
import pytest

from drivebench.config import REPO_ROOT, settings
from drivebench.web import app as app_module
from drivebench.web import heap
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, serve_app, wait_until

pytestmark = pytest.mark.slow  # every test serves 300 cold uploads in uvicorn: `make test-quick` leaves them out

UPLOADS = 300
SHIPPED_EDS = sorted((REPO_ROOT / "device_profiles" / "eds").glob("*.eds"))
SERVO_EDS = REPO_ROOT / "device_profiles" / "eds" / "generic-cia402-servo.eds"
LAST = "zz-servo"
"""A copy of the servo's EDS under its own id, in the last file the loader reads."""
BROKEN = "up-broken.eds"


def store_uploads(folder: Path) -> int:
    """The shipped EDS files in turn under ids of their own, one broken file, and the servo read last."""
    folder.mkdir(parents=True)
    for n in range(UPLOADS):
        content = SHIPPED_EDS[n % len(SHIPPED_EDS)].read_bytes()
        (folder / f"up-{n:03d}.eds").write_bytes(re.sub(rb"ProfileId=[^\r\n]*", f"ProfileId=up-{n:03d}".encode(),
                                                        content, count=1))
    (folder / BROKEN).write_bytes(b'{"id": "json-named-eds"}\n')  # a JSON profile stored as .eds: refused
    (folder / f"{LAST}.eds").write_bytes(re.sub(rb"ProfileId=[^\r\n]*", f"ProfileId={LAST}".encode(),
                                                SERVO_EDS.read_bytes(), count=1))
    return UPLOADS + 2


def plant_file(folder: Path) -> Path:
    """One simulated servo with its shipped profile (the plant does not wait for the uploads)."""
    path = folder / "plant.json"
    path.write_text(json.dumps({"name": "Lazy plant", "bus": f"virtual:{fresh_channel()}@500000",
                                "nodes": [{"node_id": 7, "profile": "generic-cia402-servo", "latency": "0ms"}]}))
    return path


def wait_until_loaded(base: str, timeout_s: float = 600) -> dict[str, object]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        profiles = httpx.get(f"{base}/api/health", timeout=60).json()["profiles"]
        if profiles["state"] == "loaded":
            return dict(profiles)
        time.sleep(0.2)
    raise AssertionError("the stored uploads did not load")


def uploaded(base: str) -> list[str]:
    return [p["id"] for p in httpx.get(f"{base}/api/profiles", timeout=60).json() if not p["builtin"]]


def test_health_answers_while_stored_uploads_load_and_the_lists_fill_up(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    stored = store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    with serve_app(create_app()) as base:
        health = httpx.get(f"{base}/api/health", timeout=60).json()
        assert health["status"] == "ok" and health["profiles"]["state"] == "loading"
        assert health["profiles"]["stored"] == stored and health["profiles"]["loaded"] < stored
        assert len(uploaded(base)) < UPLOADS + 1  # what is loaded so far
        page = httpx.get(f"{base}/profiles", headers={"Accept-Language": "de"}, timeout=60).text
        listed = len(re.findall(r'class="badge uploaded"', page))
        shown = re.search(r"lade gespeicherte Profile: (\d+) von (\d+)", page)
        assert shown is not None or listed == UPLOADS + 1, "the page lists a part without saying so"
        if shown is not None:
            assert int(shown[2]) == stored

        assert wait_until_loaded(base) == {"state": "loaded", "loaded": stored, "stored": stored}
        assert len(uploaded(base)) == UPLOADS + 1
        errors = httpx.get(f"{base}/api/profiles/load-errors", timeout=60).json()
        assert [e["file"] for e in errors] == [BROKEN]
        page = httpx.get(f"{base}/profiles", timeout=60).text
        assert "loading stored profiles" not in page


def test_a_node_given_a_stored_upload_waits_for_it_and_reads(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    with serve_app(create_app(plant_file=plant_file(tmp_path))) as base:
        assert httpx.get(f"{base}/api/health", timeout=60).json()["profiles"]["state"] == "loading"
        [session] = httpx.get(f"{base}/api/sessions", timeout=60).json()
        assert LAST not in uploaded(base)
        node = httpx.post(f"{base}/api/sessions/{session['id']}/nodes", json={"node_id": 7, "profile_id": LAST},
                          headers={"X-DriveBench": "1"}, timeout=600)
        assert node.status_code == 201, node.text
        assert node.json()["profile_id"] == LAST
        read = httpx.get(f"{base}/api/sessions/{session['id']}/nodes/7/parameters/0x1018.1", timeout=60)
        assert read.status_code == 200, read.text
        assert httpx.get(f"{base}/api/profiles/{LAST}", timeout=60).status_code == 200


def test_a_server_of_its_own_settles_its_heap_once_the_stored_uploads_are_read(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``drivebench serve`` (``heap.hold``, ``settle_heap``): the full collection over what the start made waits
    until the stored uploads are read (they are part of it), so the first answers do not wait for it (issue 33)."""
    store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    heap.hold()
    try:
        with serve_app(create_app(settle_heap=True)) as base:
            collecting, frozen = gc.isenabled(), gc.get_freeze_count()  # before the answer: still loading then
            assert httpx.get(f"{base}/api/health", timeout=60).json()["profiles"]["state"] == "loading"
            assert (collecting, frozen) == (False, 0), "the start collected its heap before the first answer"
            wait_until_loaded(base)
            assert wait_until(gc.isenabled, 120), "the collector stayed off after the uploads were read"
            assert gc.get_freeze_count() > 10_000
    finally:
        gc.enable()
        gc.unfreeze()


def test_a_big_folder_is_not_waited_for_before_the_first_answer(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The start waits (``UPLOADS_GRACE_S``) only for a folder small enough to be read in that time: with hundreds
    of uploads the wait only put off the first answer, and the loading thread took the CPU the start needed (issue
    33). The grace is made long here, so a start that waits for this folder answers ``loaded``."""
    stored = store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    monkeypatch.setattr(app_module, "UPLOADS_GRACE_S", 600.0)
    with serve_app(create_app(), start_timeout_s=600) as base:
        profiles = httpx.get(f"{base}/api/health", timeout=60).json()["profiles"]
        assert profiles["state"] == "loading" and profiles["stored"] == stored
        assert wait_until_loaded(base) == {"state": "loaded", "loaded": stored, "stored": stored}


def test_a_few_stored_uploads_are_there_at_the_first_answer(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "user-profiles"
    folder.mkdir()
    for n in range(3):
        (folder / f"up-{n}.eds").write_bytes(re.sub(rb"ProfileId=[^\r\n]*", f"ProfileId=up-{n}".encode(),
                                                    SERVO_EDS.read_bytes(), count=1))
    monkeypatch.setattr(settings, "user_profiles_dir", folder)
    monkeypatch.setattr(app_module, "UPLOADS_GRACE_S", 600.0)
    with serve_app(create_app(), start_timeout_s=600) as base:
        assert httpx.get(f"{base}/api/health", timeout=60).json()["profiles"] == {
            "state": "loaded", "loaded": 3, "stored": 3}
        assert sorted(uploaded(base)) == ["up-0", "up-1", "up-2"]


def test_a_big_folder_begins_loading_once_the_first_answer_is_sent(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The loading thread (and the one building FastAPI's route copies) begins once the server has sent its first
    answer (``web/first_answer.py``): before, it took its share of the CPU while that answer was made (issue 33)."""
    stored = store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    with serve_app(create_app()) as base:
        first = httpx.get(f"{base}/api/health", timeout=60).json()["profiles"]
        assert first == {"state": "loading", "loaded": 0, "stored": stored}
        assert wait_until_loaded(base) == {"state": "loaded", "loaded": stored, "stored": stored}


def test_a_first_request_that_needs_a_stored_upload_begins_the_loading_and_gets_it(
        tmp_path: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    store_uploads(tmp_path / "user-profiles")
    monkeypatch.setattr(settings, "user_profiles_dir", tmp_path / "user-profiles")
    with serve_app(create_app()) as base:
        answer = httpx.get(f"{base}/api/profiles/{LAST}", timeout=600)
        assert answer.status_code == 200, answer.text
        assert answer.json()["id"] == LAST
