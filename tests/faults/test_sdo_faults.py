"""SDO faults of issue #10 on the demo plant, through the real path (HTTP API and page fragments -> parameter
service -> protocol -> virtual CAN bus -> simulated node): a node that stops answering mid segmented transfer,
answers with the wrong toggle bit or for another object, aborts every request (an abort storm), and a server
killed during a parameter-set download.

In every case: the user reads what happened in words, the other nodes keep working meanwhile, nothing stored is
lost, and the node answers again as soon as the fault is cleared (same server, same session).

C00099 (firmware version, 11 bytes) is node 5's segmented object: two segments of 7 and 4 bytes.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen import sdo_fast
from drivebench.services.sets.parameter_sets import ParameterSetStore
from drivebench.services.storage import database
from drivebench.services.users import audit
from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

SESSION = "demo-plant"
NODE = f"/api/sessions/{SESSION}/nodes"
FAULTS = f"/api/sessions/{SESSION}/simulator/nodes/{{node}}/faults"
HTMX = {"HX-Request": "true"}


def plant_of(api: TestClient) -> Plant:
    plant: Plant = api.app.state.drivebench.plants[SESSION]  # type: ignore[attr-defined]
    return plant


def set_faults(api: TestClient, node: int, **faults: Any) -> dict[str, Any]:
    response = api.put(FAULTS.format(node=node), json=faults)
    assert response.status_code == 200, response.text
    body: dict[str, Any] = response.json()
    return body


def read(api: TestClient, node: int, ref: str) -> httpx.Response:
    return api.get(f"{NODE}/{node}/parameters/{ref}")


def while_pending(work: Callable[[], httpx.Response], other: Callable[[], httpx.Response]
                  ) -> tuple[httpx.Response, list[httpx.Response]]:
    """Run ``work``; meanwhile keep running ``other`` (another node) until ``work`` is done."""
    with ThreadPoolExecutor(max_workers=2) as pool:
        pending = pool.submit(work)
        others = [other()]
        while not pending.done():
            others.append(other())
        return pending.result(timeout=60), others


# --- the fault switch --------------------------------------------------------------------------------------
def test_faults_are_switched_per_simulated_node_and_refused_on_a_real_bus(demo_api: TestClient) -> None:
    body = set_faults(demo_api, 5, silent_after_segments=3, abort_code="0x08000000", abort_every=4)
    assert body["faults"]["abort_code"] == 0x08000000
    assert body["active"] == ["stops answering after 3 segments of a segmented transfer",
                              "aborts every 4th request with 0x08000000"]
    assert plant_of(demo_api).nodes[5].faults.faults.silent_after_segments == 3
    assert demo_api.get(FAULTS.format(node=12)).json()["active"] == []  # only node 5
    assert demo_api.delete(FAULTS.format(node=5)).json()["active"] == []

    assert demo_api.put(FAULTS.format(node=5), json={"abort_code": "general"}).status_code == 422
    assert demo_api.put(FAULTS.format(node=5), json={"sparks": True}).status_code == 422
    missing = demo_api.get(FAULTS.format(node=44))
    assert missing.status_code == 404 and "no node 44" in missing.json()["detail"]

    opened = demo_api.post("/api/sessions", json={"interface": "virtual", "channel": fresh_channel(), "name": "real"})
    assert opened.status_code == 201, opened.text
    refused = demo_api.put(f"/api/sessions/{opened.json()['id']}/simulator/nodes/5/faults", json={"wrong_toggle": True})
    assert refused.status_code == 409
    assert "simulated sessions only" in refused.json()["detail"]


# --- one read, each fault ----------------------------------------------------------------------------------
CASES = [
    pytest.param({"silent_after_segments": 1}, "C00099", 504,
                 "Node 5 stopped answering during a segmented transfer of C00099 after 1 of 2 segments",
                 id="silent-mid-segmented"),
    pytest.param({"wrong_toggle": True}, "C00099", 502,
                 "Node 5: toggle bit error: the node answered out of step during the segmented transfer of "
                 "0x5F9C sub 0 (C00099)", id="wrong-toggle"),
    pytest.param({"index_offset": 1}, "C00099", 502,
                 "Node 5: answer for 0x5F9D sub 0 while 0x5F9C sub 0 (C00099) was asked", id="wrong-index-segmented"),
    pytest.param({"index_offset": 1}, "C00061", 502,
                 "Node 5: answer for 0x5FC3 sub 0 while 0x5FC2 sub 0 (C00061) was asked", id="wrong-index-expedited"),
    pytest.param({"subindex_offset": 1}, "C00061", 502,
                 "Node 5: answer for 0x5FC2 sub 1 while 0x5FC2 sub 0 (C00061) was asked", id="wrong-subindex"),
    pytest.param({"abort_code": 0x06060000}, "C00061", 502,
                 "Node 5: 0x5FC2sub0: SDO abort 0x06060000", id="abort"),
]


@pytest.mark.parametrize(("faults", "ref", "status", "words"), CASES)
def test_fault_is_told_in_words_others_keep_working_and_it_recovers(demo_api: TestClient, app_db_url: str,
                                                                    faults: dict[str, Any], ref: str, status: int,
                                                                    words: str) -> None:
    profile = ProfileRegistry().get("lenze-8400-motec-canopen")
    stored = ParameterSetStore(app_db_url).create("kept", profile, {"C00088": 1020, "C00011": 1500}, user="t")
    before = read(demo_api, 5, ref)
    assert before.status_code == 200, before.text
    set_faults(demo_api, 5, **faults)

    failed, others = while_pending(lambda: read(demo_api, 5, ref), lambda: read(demo_api, 12, "C00011"))
    assert failed.status_code == status, failed.text
    problem = failed.json()
    assert failed.headers["content-type"].startswith("application/problem+json")
    assert problem["detail"].startswith(words), problem
    assert problem["node"] == 5 and problem["object"].lower().startswith(before.json()["index"].lower())
    assert all(other.status_code == 200 for other in others), [o.text for o in others]
    assert read(demo_api, 3, "P0700").status_code == 200  # the MICROMASTER too

    # the page: the row's Read button gets the same words beside it, with the same status
    row = demo_api.post(f"/ui/sessions/{SESSION}/nodes/5/parameters/{ref}/read", headers=HTMX)
    assert row.status_code == status
    assert 'role="alert"' in row.text and words.split(" (")[0].replace("0x5F9C sub 0", "") in row.text

    set_faults(demo_api, 5)  # {}: cleared
    again = read(demo_api, 5, ref)
    assert again.status_code == 200, again.text
    assert again.json()["raw"] == before.json()["raw"]
    assert ParameterSetStore(app_db_url).get(stored.info.id).values == {"C00088": 1020, "C00011": 1500}


def test_abort_text_is_the_manuals_and_the_code_travels(demo_api: TestClient) -> None:
    set_faults(demo_api, 5, abort_code="0x06060000")
    problem = read(demo_api, 5, "C00061").json()
    assert problem["abort_code"] == "0x06060000" and problem["abort_text"] and problem["abort_text"] in \
        problem["detail"]
    assert problem["abort_text"] == "Access denied because of hardware error"  # the profile's abort_texts
    set_faults(demo_api, 5)


# --- read-all with faults ----------------------------------------------------------------------------------
def run_job(api: TestClient, path: str, on_the_way: Callable[[], None] | None = None) -> dict[str, Any]:
    started = api.post(path, json={})
    assert started.status_code == 202, started.text
    job: dict[str, Any] = started.json()
    end = time.monotonic() + 60
    while job["state"] == "running":
        assert time.monotonic() < end, job
        if on_the_way is not None:
            on_the_way()
        time.sleep(0.02)
        job = api.get(f"/api/jobs/{job['id']}").json()
    return job


def test_read_all_keeps_what_it_read_and_names_each_failure(demo_api: TestClient) -> None:
    set_faults(demo_api, 5, abort_code="0x08000000", abort_every=3)
    job = run_job(demo_api, f"{NODE}/5/read-all")
    assert job["state"] == "incomplete"  # some values are missing (issue 28 item 5)
    issues = job["issues"]
    total = job["progress"]["total"]
    assert issues and len(issues) < total
    assert all(i["abort_code"] == "0x08000000" and "SDO abort 0x08000000" in i["detail"] for i in issues)
    listed = demo_api.get(f"{NODE}/5/parameters").json()["parameters"]
    with_values = [p for p in listed if p["last"] is not None]
    assert len(with_values) >= total - len(issues) - 2  # what was read is kept (SDO2 set-up reads aside)

    set_faults(demo_api, 5)
    again = run_job(demo_api, f"{NODE}/5/read-all")
    assert again["state"] == "done" and again["issues"] == []


def test_read_all_gives_up_on_a_node_answering_out_of_step(demo_api: TestClient) -> None:
    set_faults(demo_api, 5, index_offset=1)
    job = run_job(demo_api, f"/api/sessions/{SESSION}/read-all")
    assert job["state"] == "incomplete"
    assert any(note.startswith("Node 5 answered out of step;") and "parameters not read" in note
               for note in job["notes"]), job["notes"]
    by_node = {issue["node"] for issue in job["issues"]}
    assert 5 in by_node and 12 not in by_node  # node 12 was read in full meanwhile
    set_faults(demo_api, 5)
    assert read(demo_api, 5, "C00061").status_code == 200


@pytest.mark.parametrize("fault", [{"late_requests": 2, "latency_ms": 900}, {"drop_requests": 2}])
def test_read_all_reads_every_parameter_of_a_node_that_missed_two_answers(demo_api: TestClient,
                                                                          fault: dict[str, int]) -> None:
    """Two requests answered too late (a busy device) or lost, then normal answers: not a silent node. The two
    reads are asked again at the end and the job says so (issue 16 item 13: two slow answers used to abandon a
    healthy drive)."""
    assert demo_api.put(f"/api/sessions/{SESSION}/sdo-settings",
                        json={"timeout_s": 0.3, "retries": 0, "use_sdo2": False}).status_code == 200
    set_faults(demo_api, 5, **fault)
    job = run_job(demo_api, f"{NODE}/5/read-all")
    assert job["state"] == "done" and job["issues"] == [], (job["issues"], job["notes"], job["result"].get("retried"))
    total = job["progress"]["total"]
    assert len(job["result"]["values"]["5"]) == total
    listed = demo_api.get(f"{NODE}/5/parameters").json()["parameters"]
    first_two = [p["ref"] for p in listed if p["access"] != "wo"][:2]
    # the two that missed their answers, and on a loaded machine maybe more
    assert job["result"]["retried"]["5"][:2] == first_two and job["result"]["failed_after_retry"]["5"] == []
    assert not any("not read" in note for note in job["notes"]), job["notes"]


def set_job_done(api: TestClient, job: dict[str, Any]) -> dict[str, Any]:
    end = time.monotonic() + 60
    while job["state"] == "running":
        assert time.monotonic() < end, job
        time.sleep(0.05)
        job = api.get(f"/api/parameter-sets/jobs/{job['id']}").json()
    return job


def test_download_keeps_writing_to_a_node_that_missed_two_answers(demo_api: TestClient) -> None:
    """A drive busy writing its memory leaves two downloads unanswered, then answers again: the parameter-set
    download writes everything after them (it gave up after two timeouts and sent nothing more), and the two show
    as failed, ready for the retry."""
    sets = "/api/parameter-sets"
    started = demo_api.post(f"{sets}/upload", json={"session_id": SESSION, "node_id": 5, "name": "Busy drive"})
    assert started.status_code == 202, started.text
    uploaded = set_job_done(demo_api, started.json())
    exported = json.loads(demo_api.get(f"{sets}/{uploaded['set_id']}/export").text)
    changes = {"C00088": 12.5, "C00039/1": 55.0, "C00324/1": 10, "C00324/2": 20, "C00324/3": 30}
    for parameter in exported["parameters"]:
        if parameter["ref"] in changes:
            parameter["value"] = changes[parameter["ref"]]
    exported["name"] = "Busy drive, changed"
    imported = demo_api.post(f"{sets}/import", files={"file": ("busy.json", json.dumps(exported).encode())})
    new_id = imported.json()["set"]["id"]
    # 1 s: the two dropped writes wait it out; a healthy answer on a loaded machine comes well within it (0.3 s did
    # not always: a clean-clone run had a third write answered late, rightly failed)
    assert demo_api.put(f"/api/sessions/{SESSION}/sdo-settings",
                        json={"timeout_s": 1.0, "retries": 0, "use_sdo2": False}).status_code == 200
    set_faults(demo_api, 5, drop_downloads=2)

    job = set_job_done(demo_api, confirmed(demo_api, "POST", f"{sets}/{new_id}/download",
                                           json={"session_id": SESSION, "node_id": 5, "confirm": 5}).json())
    statuses = {line["ref"]: line["status"] for line in job["report"] if line["ref"] in changes}
    # the two dropped fail and the download writes on after them (on a loaded machine maybe one more times out)
    assert list(statuses.values()).count("failed") >= 2 and set(statuses.values()) == {"failed", "written"}, \
        job["report"]
    assert not any("stopped answering" in (line["detail"] or "") for line in job["report"])

    retried = set_job_done(demo_api, confirmed(demo_api, "POST",
                                               f"/api/parameter-downloads/{job['download_id']}/retry",
                                               json={"confirm": 5}).json())
    assert {line["status"] for line in retried["report"] if line["ref"] in changes} <= {"written", "unchanged"}
    assert demo_api.get(f"{NODE}/5/parameters/C00088").json()["display"] == "12.50 A"


def test_abort_storm_keeps_the_server_responsive_and_leaks_nothing(demo_api: TestClient) -> None:
    """Every request of node 5 and 12 aborted: hundreds of aborts per second from one read-all of every node."""
    for node in (5, 12):
        set_faults(demo_api, node, abort_code="0x08000000")
    health: list[int] = []
    job = run_job(demo_api, f"/api/sessions/{SESSION}/read-all",
                  on_the_way=lambda: health.append(demo_api.get("/api/health").status_code))
    assert job["state"] == "incomplete"
    assert health and set(health) == {200}
    failed = {(i["node"], i["item"]) for i in job["issues"] if i["abort_code"] == "0x08000000"}
    assert len(failed) > 200
    assert not any(i["node"] == 3 and i["abort_code"] == "0x08000000" for i in job["issues"])

    session = demo_api.app.state.drivebench.manager.get(SESSION)  # type: ignore[attr-defined]
    for client in session.network.nodes.values():
        for channel in client.channels:
            assert not channel.lock.locked()
            assert channel.client.responses.empty()
            uploader = sdo_fast._UPLOADERS.get(channel)
            assert uploader is None or uploader._transfer is None

    for node in (5, 12):
        set_faults(demo_api, node)
    assert read(demo_api, 5, "C00061").json()["raw"] == 43
    assert read(demo_api, 12, "C00011").status_code == 200


# --- server killed during a parameter-set download ---------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _changed(profile: Any, count: int) -> dict[str, int]:
    """A partial set: ``count`` plain numeric settings of node 5, one step from their defaults (still in range)."""
    from drivebench.services.sets.parameter_sets import catalog_for, defaults_of

    catalog = catalog_for(profile)
    changed: dict[str, int] = {}
    for ref, raw in defaults_of(profile, 5).items():
        entry = catalog.resolve(ref).entry
        if (len(changed) < count and isinstance(raw, int) and not isinstance(raw, bool) and entry.access.writable
                and not (entry.reset_required or entry.selection or entry.bits or entry.factor != 1)
                and catalog.resolve(ref).index >= 0x2000 and (entry.max is None or raw + 1 <= entry.max)):
            changed[ref] = raw + 1
    assert len(changed) == count
    return changed


def test_server_killed_during_a_download_loses_nothing_and_says_so_at_next_start(tmp_path: Path, app_db_url: str
                                                                                 ) -> None:
    """The issue #9 test kills a process running the download service; this one kills the web server itself
    (SIGKILL, mid write: the audit row still says "sending") and starts a new one on the same database."""
    database.upgrade_to_head(app_db_url)
    profile = ProfileRegistry().get("lenze-8400-motec-canopen")
    target = ParameterSetStore(app_db_url).create("slow download", profile, _changed(profile, 6), user="t")
    port = _free_port()
    env = {**os.environ, "DRIVEBENCH_DATABASE_URL": app_db_url}
    server = subprocess.Popen([sys.executable, "-m", "drivebench.cli", "serve", "--demo", "--port", str(port)],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as remote:
            end = time.monotonic() + 60
            while True:
                assert server.poll() is None, server.stdout.read() if server.stdout else ""
                assert time.monotonic() < end, "the server did not start"
                try:
                    if remote.get("/api/health").status_code == 200:
                        break
                except httpx.TransportError:
                    time.sleep(0.1)
            # every SDO request of node 5 takes 0.4 s: each write is "sending" for most of its time
            assert remote.put(f"/api/sessions/{SESSION}/sdo-settings",
                              json={"timeout_s": 5, "retries": 0, "use_sdo2": False}).status_code == 200
            assert remote.put(FAULTS.format(node=5), json={"latency_ms": 400}).status_code == 200
            started = remote.post(f"/api/parameter-sets/{target.info.id}/download",
                                  json={"session_id": SESSION, "node_id": 5})
            assert started.status_code == 202, started.text
            end = time.monotonic() + 90
            while not (any(e.result == "written" for e in audit.entries(app_db_url))
                       and any(e.result == "sending" for e in audit.entries(app_db_url))):
                assert time.monotonic() < end, "no write under way"
                time.sleep(0.02)
        server.send_signal(signal.SIGKILL)
        server.wait(10)
    finally:
        if server.poll() is None:
            server.kill()
            server.wait(10)

    logged = audit.entries(app_db_url)
    assert [e.result for e in logged].count("sending") == 1  # the write under way when the server died
    assert ParameterSetStore(app_db_url).get(target.info.id).values == target.values

    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as restarted:
        [download] = restarted.get("/api/parameter-downloads").json()
        assert download["state"] == "interrupted"
        page = restarted.get(f"/parameter-sets/downloads/{download['id']}", headers=HTMX)
        assert page.status_code == 200
        assert "The server stopped during this download" in page.text
        rows = restarted.get("/api/audit").json()
        assert [row["result"] for row in rows].count("sending") == 1
        assert restarted.get(f"/api/parameter-sets/{target.info.id}").json()["name"] == "slow download"
