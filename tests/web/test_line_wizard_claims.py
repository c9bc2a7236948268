"""The "New line" wizard with two servers on one database (README "Deploying for a plant"): a step's claim lives in
the database, so server B sees server A's live step as running (not interrupted) and refuses to start it; a server
that stops renewing its claim (frozen, or gone) leaves the step ``interrupted`` once its lease runs out, and B runs it
again. Server A is a `drivebench serve --plant plants/new-line.json` process of its own (the real simulator, held by
a simulated device that answers slowly), B the app in this process; SQLite file and PostgreSQL alike."""

from __future__ import annotations

import json
import os
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.storage import database
from tests.confirming import confirmed
from tests.conftest import _free_port, fresh_channel, wait_until
from tests.line_wizard_project import new_line_project
from tests.transport.test_multiprocess import CliProcess
from tests.web.test_line_wizard_api import WIZARD, new_line_app

pytestmark = pytest.mark.slow
SLOW_NODE = "/api/sessions/new-line/simulator/nodes/23/faults"
LEASE_S = 3


@pytest.fixture
def shared_db(database_url: str, monkeypatch: pytest.MonkeyPatch) -> str:
    database.upgrade_to_head(database_url)
    monkeypatch.setattr(settings, "database_url", database_url)
    monkeypatch.setattr(settings, "sdo_timeout_s", 30.0)  # the slow device answers, it does not time out
    return database_url


@pytest.fixture
def server_a(shared_db: str, tmp_path: Path) -> Iterator[CliProcess]:
    env = {"DRIVEBENCH_DATABASE_URL": shared_db, "DRIVEBENCH_SDO_TIMEOUT_S": "30",
           "DRIVEBENCH_WIZARD_STEP_LEASE_S": str(LEASE_S), "DRIVEBENCH_SECRET_KEY_FILE": str(tmp_path / "key")}
    server = CliProcess("serve", "--plant", "plants/new-line.json", "--port", str(_free_port()), env=env)
    try:
        yield server
    finally:
        if server.process.poll() is None:
            os.kill(server.process.pid, signal.SIGCONT)
            server.process.kill()
        server.process.wait(timeout=30)


def _in_background(client: httpx.Client, run_id: int, name: str) -> dict[str, Any]:
    """POST the step in a thread; ``answer`` holds its status (or the error when the server went away)."""
    outcome: dict[str, Any] = {}

    def post() -> None:
        try:
            outcome["answer"] = confirmed(client, "POST", f"{WIZARD}/{run_id}/steps/{name}", json={})
        except httpx.HTTPError as exc:
            outcome["error"] = exc

    outcome["thread"] = thread = threading.Thread(target=post, daemon=True)
    thread.start()
    return outcome


def _serves(client: httpx.Client) -> bool:
    try:
        return client.get("/api/sessions/new-line").status_code == 200
    except httpx.HTTPError:
        return False


def _step(api: TestClient, run_id: int, name: str) -> dict[str, Any]:
    return dict(api.get(f"{WIZARD}/{run_id}").json()["steps"][name])


def _state(api: TestClient, run_id: int, name: str) -> str:
    return str(_step(api, run_id, name)["state"])


def test_a_step_running_on_another_server_is_shown_running_refused_and_interrupted_when_its_lease_ends(
        server_a: CliProcess, registry: ProfileRegistry) -> None:
    url_a = server_a.wait_for_line(r"DriveBench on (http://\S+)").group(1)
    with httpx.Client(base_url=url_a, timeout=120) as a, TestClient(new_line_app(fresh_channel())) as b:
        assert wait_until(lambda: _serves(a), 60), "".join(server_a.output)
        opened = a.post("/api/line-projects/import?filename=new-line.json",
                        content=json.dumps(new_line_project(registry)).encode())
        assert opened.status_code == 201, opened.text
        run_id = a.post(WIZARD, json={"project_id": opened.json()["id"]}).json()["id"]
        for name in ("scan", "assign"):
            answer = confirmed(a, "POST", f"{WIZARD}/{run_id}/steps/{name}", json={})
            assert answer.status_code == 200, answer.text
        assert a.put(SLOW_NODE, json={"latency_ms": 1500}).status_code == 200  # each read of node 23: 1.5 s

        # A checks the line, held by its slow axis: B sees the step running on A and does not start it
        first = _in_background(a, run_id, "boot_check")
        assert wait_until(lambda: _state(b, run_id, "boot_check") == "running", 60), _step(b, run_id, "boot_check")
        run = b.get(f"{WIZARD}/{run_id}").json()
        assert run["claim"]["step"] == "boot_check"
        refused = confirmed(b, "POST", f"{WIZARD}/{run_id}/steps/boot_check", json={})
        assert refused.status_code == 409, refused.text
        assert "running on another DriveBench server (host " in refused.json()["detail"]
        assert b.put(f"{WIZARD}/{run_id}/assignments", json={}).status_code == 409  # nothing changes under it
        page = b.get(f"/sessions/new-line/line-wizard/{run_id}")
        assert page.status_code == 200
        assert a.put(SLOW_NODE, json={}).status_code == 200
        first["thread"].join(120)
        assert first["answer"].status_code == 200, first["answer"].text
        done = b.get(f"{WIZARD}/{run_id}").json()
        assert done["steps"]["boot_check"]["state"] == "done", done["steps"]["boot_check"]["lines"]
        assert done["claim"] is None

        # A runs it again and freezes mid-step (its lease is no longer renewed): once the lease ran out, B reads the
        # step interrupted and runs it itself
        assert a.put(SLOW_NODE, json={"latency_ms": 1500}).status_code == 200
        _in_background(a, run_id, "boot_check")
        assert wait_until(lambda: _state(b, run_id, "boot_check") == "running", 60), _step(b, run_id, "boot_check")
        os.kill(server_a.process.pid, signal.SIGSTOP)
        assert _state(b, run_id, "boot_check") == "running"
        assert wait_until(lambda: _state(b, run_id, "boot_check") == "interrupted", LEASE_S * 10)
        again = confirmed(b, "POST", f"{WIZARD}/{run_id}/steps/boot_check", json={})
        assert again.status_code == 200, again.text
        assert again.json()["steps"]["boot_check"]["runs"] == 3
        assert again.json()["steps"]["boot_check"]["state"] in {"done", "failed"}
