"""Two `drivebench serve --demo` processes on one PostgreSQL database, as two lines of a plant with one store: each
runs its own simulated plant (its own bus, its own node 5), both read and write the same sets, downloads, audit
log, users, sessions, share links and sign-in locks. A server killed with SIGKILL mid-download loses no row that
was committed."""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.storage.models import DownloadRow
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from tests.confirming import confirmed
from tests.conftest import _free_port, wait_until
from tests.pg_cluster import PostgresCluster
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = [pytest.mark.postgresql, pytest.mark.slow]

SESSION = "demo-plant"
SETS = "/api/parameter-sets"
USERS = {"root": Role.ADMIN, "eve": Role.ENGINEER, "anna": Role.ENGINEER, "dora": Role.ENGINEER,
         "otto": Role.VIEWER, "vera": Role.VIEWER}
PASSWORD = "a long password"


class _Http:
    """httpx's functions with a long timeout (a loaded 2-core machine runs three servers here) and, unlike a
    Client, no cookie jar: each test says which session cookie it sends."""

    def __getattr__(self, method: str) -> Any:
        return functools.partial(getattr(httpx, method), timeout=60)


HTTP = _Http()


@dataclass
class Plant:
    """The database and the API tokens of its users; the servers on it."""

    tmp: Path
    db_url: str
    tokens: dict[str, str]
    servers: list[CliProcess] = field(default_factory=list)

    def serve(self, *options: str) -> str:
        """One more `drivebench serve --demo` on this database; its base URL."""
        env = {"DRIVEBENCH_DATABASE_URL": self.db_url,
               # one key for every server of the database: a cookie signed by one is read by the others
               "DRIVEBENCH_SECRET_KEY_FILE": str(self.tmp / "secret_key")}
        server = CliProcess("serve", "--demo", "--port", str(_free_port()), *options, env=env)
        self.servers.append(server)
        url = server.wait_for_line(r"DriveBench on (http://\S+)").group(1)
        assert wait_until(lambda: _demo_ready(url, self.tokens["root"]), START_TIMEOUT_S), "".join(server.output)
        return url

    def api(self, user: str) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[user]}"}


def _demo_ready(url: str, token: str) -> bool:
    try:
        sessions = HTTP.get(f"{url}/api/sessions", headers={"Authorization": f"Bearer {token}"})
    except httpx.HTTPError:
        return False
    return sessions.status_code == 200 and any(s["id"] == SESSION for s in sessions.json())


@pytest.fixture(scope="module")
def plant(postgres: PostgresCluster, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Plant]:
    db_url = postgres.new_database()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", db_url)
        database.upgrade_to_head(db_url)
        tokens = {}
        for name, role in USERS.items():
            accounts.create_user(name, PASSWORD, role)
            tokens[name] = accounts.issue_token(name, "two servers", role).secret
    running = Plant(tmp_path_factory.mktemp("two-servers"), db_url, tokens)
    try:
        yield running
    finally:
        for server in running.servers:
            with contextlib.suppress(AssertionError):
                server.stop()
        database.dispose(db_url)
        postgres.drop_database(db_url)


@pytest.fixture(scope="module")
def line_a(plant: Plant) -> str:
    return plant.serve()


@pytest.fixture(scope="module")
def line_b(plant: Plant) -> str:
    return plant.serve()


def finish(url: str, headers: dict[str, str], job: dict[str, Any], deadline_s: float = 60) -> dict[str, Any]:
    end = time.monotonic() + deadline_s
    while job["state"] == "running":
        assert time.monotonic() < end, f"job {job['id']} still running"
        time.sleep(0.05)
        job = HTTP.get(f"{url}{SETS}/jobs/{job['id']}", headers=headers).json()
    return job


def upload(url: str, headers: dict[str, str], name: str) -> int:
    started = HTTP.post(f"{url}{SETS}/upload", json={"session_id": SESSION, "node_id": 5, "name": name},
                         headers=headers, timeout=60)
    assert started.status_code == 202, started.text
    job = finish(url, headers, started.json())
    assert job["state"] == "done", job
    return int(job["set_id"])


def write_c88(url: str, headers: dict[str, str], value: float) -> None:
    written = HTTP.put(f"{url}/api/sessions/{SESSION}/nodes/5/parameters/C00088", json={"value": value},
                        headers=headers, timeout=60)
    assert written.status_code == 200, written.text


def test_sets_downloads_and_audit_rows_of_both_servers_are_one_history(plant: Plant, line_a: str,
                                                                         line_b: str) -> None:
    eve, anna = plant.api("eve"), plant.api("anna")
    write_c88(line_a, eve, 8)  # line A's drive: 8 A (audit row of eve on A)
    set_id = upload(line_a, eve, "Conveyor from line A")
    assert [s["name"] for s in HTTP.get(f"{line_b}{SETS}", headers=anna).json()] == ["Conveyor from line A"]

    started = confirmed(HTTP, "POST", f"{line_b}{SETS}/{set_id}/download",
                        json={"session_id": SESSION, "node_id": 5, "confirm": "5"},  # the node it may move
                        headers=anna, timeout=60)  # line B's own drive gets line A's values
    assert started.status_code == 202, started.text
    job = finish(line_b, anna, started.json())
    assert job["download_state"] == "done", job
    assert HTTP.get(f"{line_b}/api/sessions/{SESSION}/nodes/5/parameters/C00088",
                     headers=anna).json()["display"] == "8.00 A"

    seen_on_a = HTTP.get(f"{line_a}/api/parameter-downloads/{job['download_id']}", headers=eve).json()
    assert (seen_on_a["state"], seen_on_a["user"], seen_on_a["counts"]["written"]) == ("done", "anna", 1)
    log = HTTP.get(f"{line_a}/api/audit", params={"node_id": 5}, headers=eve).json()
    rows = {(e["user"], e["origin"].split()[0], e["new_value"], e["result"]) for e in log}
    assert {("eve", "parameters", "8.00 A", "written"), ("anna", "download", "8.00 A", "written")} <= rows


def test_concurrent_edits_of_one_set_one_wins_the_other_gets_409_in_words(plant: Plant, line_a: str,
                                                                          line_b: str) -> None:
    set_id = upload(line_a, plant.api("eve"), "Edited on two lines")
    start = threading.Barrier(2)
    answers: dict[str, httpx.Response] = {}

    def edit(user: str, url: str, amps: float) -> None:
        start.wait()
        answers[user] = HTTP.patch(f"{url}{SETS}/{set_id}", json={"version": 1, "values": {"C00088": amps}},
                                    headers=plant.api(user), timeout=60)

    editors = [threading.Thread(target=edit, args=("eve", line_a, 11.0)),
               threading.Thread(target=edit, args=("anna", line_b, 12.0))]
    for editor in editors:
        editor.start()
    for editor in editors:
        editor.join()
    assert sorted(a.status_code for a in answers.values()) == [200, 409], {u: a.text for u, a in answers.items()}
    winner, loser = sorted(answers, key=lambda user: answers[user].status_code)
    refused = answers[loser].json()
    assert refused["title"] == "Conflict" and answers[loser].headers["content-type"] == "application/problem+json"
    assert f"was changed by {winner} at " in refused["detail"]
    assert "it is now version 2, and your change was made to version 1. Nothing was saved." in refused["detail"]
    history = HTTP.get(f"{line_b}{SETS}/{set_id}/history", headers=plant.api("anna")).json()
    assert [(v["version"], v["created_by"]) for v in history] == [(2, winner), (1, "eve")]


def test_a_user_disabled_on_one_server_is_refused_on_the_other(plant: Plant, line_a: str, line_b: str) -> None:
    signed_in = HTTP.post(f"{line_b}/api/auth/login", json={"name": "dora", "password": PASSWORD})
    assert signed_in.status_code == 200, signed_in.text
    cookie = {"drivebench_session": signed_in.cookies["drivebench_session"]}
    assert HTTP.get(f"{line_b}/api/auth/me", cookies=cookie).status_code == 200
    assert HTTP.get(f"{line_b}/api/auth/me", headers=plant.api("dora")).status_code == 200

    disabled = HTTP.patch(f"{line_a}/api/users/dora", json={"disabled": True}, headers=plant.api("root"))
    assert disabled.status_code == 200, disabled.text
    assert wait_until(lambda: HTTP.get(f"{line_b}/api/auth/me", cookies=cookie).status_code == 401,
                      accounts.DIRECTORY_TTL_S + 10)
    assert HTTP.get(f"{line_b}/api/auth/me", headers=plant.api("dora")).status_code == 401
    enabled = HTTP.patch(f"{line_b}/api/users/dora", json={"disabled": False}, headers=plant.api("root"))
    assert enabled.status_code == 200, enabled.text
    for url in (line_a, line_b):  # enabled again: neither her old session nor her old token comes back
        assert HTTP.get(f"{url}/api/auth/me", cookies=cookie).status_code == 401
        refused = HTTP.get(f"{url}/api/auth/me", headers=plant.api("dora"))
        assert refused.status_code == 401 and "unknown or revoked" in refused.json()["detail"]


def test_a_sign_out_on_one_server_ends_the_session_on_the_other(line_a: str, line_b: str) -> None:
    signed_in = HTTP.post(f"{line_a}/api/auth/login", json={"name": "vera", "password": PASSWORD})
    cookie = {"drivebench_session": signed_in.cookies["drivebench_session"]}
    assert HTTP.get(f"{line_b}/api/auth/me", cookies=cookie).json()["name"] == "vera"
    csrf = HTTP.get(f"{line_a}/api/auth/me", cookies=cookie).json()["csrf_token"]
    assert HTTP.post(f"{line_a}/api/auth/logout", cookies=cookie,
                      headers={"X-CSRF-Token": csrf}).status_code == 204
    assert HTTP.get(f"{line_b}/api/auth/me", cookies=cookie).status_code == 401


def test_a_share_link_made_on_one_server_opens_on_the_other_until_revoked_there(plant: Plant, line_a: str,
                                                                                line_b: str) -> None:
    made = HTTP.post(f"{line_a}/api/share-links", json={"ttl_minutes": 30, "label": "vendor support"},
                      headers=plant.api("eve"))
    assert made.status_code == 201, made.text
    token, link_id = made.json()["token"], made.json()["id"]
    page = HTTP.get(f"{line_b}/remote/{token}")
    assert page.status_code == 200 and "vendor support" in page.text
    assert HTTP.get(f"{line_b}/api/health/nodes", headers={"Authorization": f"Bearer {token}"}
                     ).status_code == 200
    assert HTTP.delete(f"{line_b}/api/share-links/{link_id}", headers=plant.api("anna")).status_code == 204
    gone = HTTP.get(f"{line_a}/api/health/nodes", headers={"Authorization": f"Bearer {token}"})
    assert gone.status_code == 401 and "not valid" in gone.json()["detail"]


def test_a_sign_in_lock_made_on_one_server_holds_on_the_other(line_a: str, line_b: str) -> None:
    for _ in range(5):
        wrong = HTTP.post(f"{line_a}/api/auth/login", json={"name": "otto", "password": "guess"})
        assert wrong.status_code == 401, wrong.text
    locked = HTTP.post(f"{line_b}/api/auth/login", json={"name": "otto", "password": PASSWORD})
    assert locked.status_code == 429, locked.text
    assert locked.json()["detail"].startswith("Too many failed sign-ins for otto: try again in ")


def test_kill_9_mid_download_loses_no_committed_row(plant: Plant, line_a: str, line_b: str) -> None:
    eve, anna = plant.api("eve"), plant.api("anna")
    set_id = upload(line_b, anna, "Line B at 10.2 A")
    slow = plant.serve("--latency", "200ms")  # a third line whose drive answers slowly: the download takes seconds
    write_c88(slow, eve, 9)
    for ref, value in (("C00011", 1400), ("C00324/1", 5), ("C00324/2", 5), ("C00324/3", 5)):
        written = HTTP.put(f"{slow}/api/sessions/{SESSION}/nodes/5/parameters/{ref}", json={"value": value},
                           headers=eve, timeout=60)  # more for the download to set back: seconds after its row
        assert written.status_code == 200, written.text
    before_kill = _committed(line_b, anna)
    started = confirmed(HTTP, "POST", f"{slow}{SETS}/{set_id}/download",
                        json={"session_id": SESSION, "node_id": 5, "confirm": "5"},  # the node it may move
                        headers=eve, timeout=60)
    assert started.status_code == 202, started.text
    job_url = f"{slow}{SETS}/jobs/{started.json()['id']}"

    def row_committed() -> bool:  # the download's row (the values read first) is stored, the job still runs
        return HTTP.get(job_url, headers=eve).json()["download_id"] is not None

    assert wait_until(row_committed, 30)
    download_id = HTTP.get(job_url, headers=eve).json()["download_id"]
    seen = HTTP.get(f"{line_b}/api/parameter-downloads/{download_id}", headers=anna).json()
    assert seen["state"] == "running"  # another server's download: line B does not call it interrupted
    killed = plant.servers[-1].process
    killed.kill()  # SIGKILL: no shutdown code runs
    assert killed.wait(timeout=60) == -9

    after_kill = _committed(line_b, anna)
    assert before_kill["audit"] <= after_kill["audit"] and before_kill["downloads"] <= after_kill["downloads"]
    assert ("eve", "parameters", "9.00 A") in {(u, o, v) for u, o, v, _ in after_kill["audit"]}
    interrupted = HTTP.get(f"{line_a}/api/parameter-downloads/{download_id}", headers=eve).json()
    assert (interrupted["state"], interrupted["user"]) == ("interrupted", "eve")  # its server process is gone
    assert HTTP.get(f"{line_a}/api/health").status_code == 200  # the other lines go on
    assert upload(line_a, eve, "After the crash") > set_id
    with database.transaction(plant.db_url) as db:
        assert db.get(DownloadRow, download_id).state == "running"  # type: ignore[union-attr]
    plant.serve()  # the killed line comes back: its dead downloads are stored as interrupted for every server
    with database.transaction(plant.db_url) as db:
        assert db.get(DownloadRow, download_id).state == "interrupted"  # type: ignore[union-attr]


def _committed(url: str, headers: dict[str, str]) -> dict[str, set[Any]]:
    audit = HTTP.get(f"{url}/api/audit", params={"limit": 1000}, headers=headers).json()
    downloads = HTTP.get(f"{url}/api/parameter-downloads", params={"limit": 500}, headers=headers).json()
    return {"audit": {(e["user"], e["origin"].split()[0], e["new_value"], e["id"]) for e in audit},
            "downloads": {(d["id"], d["user"], d["set_id"]) for d in downloads}}
