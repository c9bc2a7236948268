"""The monitor's REST API on a simulated plant: snapshot, filter, pause/reset, recordings, device counters."""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.services.monitoring import recording
from drivebench.web.app import create_app
from tests.conftest import wait_for_value
from tests.web.monitor_plant import SESSION_ID, write_plant

API = f"/api/sessions/{SESSION_ID}/monitor"


@pytest.fixture
def api(tmp_path: Path, channel: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    monkeypatch.setattr(recording, "recordings_dir", lambda: tmp_path / "recordings")
    app = create_app(plant_file=write_plant(tmp_path), plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as test_client:
        yield test_client


def _wait_frames(api: TestClient, minimum: int) -> dict[str, object]:
    def counted() -> dict[str, Any] | None:
        body: dict[str, Any] = api.get(API).json()
        return body if body["totals"]["frames"] >= minimum else None
    return wait_for_value(counted, 15, "telegrams counted")


def test_snapshot_filter_pause_reset(api: TestClient) -> None:
    body = _wait_frames(api, 5)
    assert body["bitrate"] == 500000 and body["trace"]
    assert api.put(f"{API}/filter", json={"nodes": [12], "services": ["Heartbeat"]}).json()["nodes"] == [12]
    rows = api.get(f"{API}/trace", params={"limit": 50}).json()["rows"]
    assert rows and all(row["cob_id"] == "0x70C" for row in rows)
    bad = api.put(f"{API}/filter", json={"cob_min": 0x700, "cob_max": 0x100})
    assert bad.status_code == 422 and bad.headers["content-type"].startswith("application/problem+json")
    assert api.post(f"{API}/pause").json() == {"paused": True}
    frozen = api.get(API).json()["totals"]["frames"]
    time.sleep(0.3)
    assert api.get(API).json()["totals"]["frames"] == frozen
    assert api.post(f"{API}/resume").json() == {"paused": False}
    assert api.post(f"{API}/reset").json()["totals"]["frames"] < frozen
    assert len(api.get(f"{API}/history").json()["points"]) <= 2


def test_recording_start_stop_list_download(api: TestClient) -> None:
    started = api.post(f"{API}/recordings", json={"format": "asc"})
    assert started.status_code == 201
    name = started.json()["name"]
    again = api.post(f"{API}/recordings", json={"format": "log"})
    assert again.status_code == 409
    _wait_frames(api, 10)
    time.sleep(0.3)
    stopped = api.post(f"{API}/recordings/stop").json()
    assert stopped["frames"] > 0
    assert api.post(f"{API}/recordings/stop").status_code == 409
    listed = api.get(f"{API}/recordings").json()["recordings"]
    assert [entry["name"] for entry in listed] == [name]
    download = api.get(f"{API}/recordings/{name}")
    assert download.status_code == 200 and "attachment" in download.headers["content-disposition"]
    assert name.endswith(".asc") and name in download.headers["content-disposition"]
    messages = list(can.ASCReader(io.StringIO(download.text)))
    assert len(messages) == stopped["frames"]
    assert api.get(f"{API}/recordings/..%2Fetc%2Fpasswd").status_code == 404
    assert api.post(f"{API}/recordings", json={"format": "mf4"}).status_code == 422


def test_device_counters_side_by_side(api: TestClient) -> None:
    first = api.get(f"{API}/device-counters/5")
    assert first.status_code == 200, first.text
    rows = {row["ref"]: row for row in first.json()["rows"]}
    assert set(rows) == {"C00360/1", "C00360/2", "C00360/3", "C00360/4", "C00360/6", "C00360/7", "C00360/8",
                         "C00360/9", "C00360/11", "C00360/12"}
    assert rows["C00360/11"]["label"] == "Telegram counter SDO1 IN" and rows["C00360/11"]["cob_ids"] == ["0x605"]
    # The monitor saw the 10 SDO requests of this read.
    assert rows["C00360/11"]["monitor"] >= 10
    assert rows["C00360/11"]["device"] >= 9  # the simulated drive counts too (up to the request for /11)
    second = {row["ref"]: row for row in api.get(f"{API}/device-counters/5").json()["rows"]}
    # Between the two reads of each counter, 10 SDO requests reached the drive and 10 responses left it; the
    # drive's 16-bit increases and the monitor's agree (nothing else talks SDO to node 5 here).
    for ref in ("C00360/11", "C00360/6", "C00360/2"):
        assert second[ref]["device_increase"] == second[ref]["monitor_increase"] == 10, ref
    assert second["C00360/12"]["device_increase"] == second["C00360/12"]["monitor_increase"] == 0
    missing = api.get(f"{API}/device-counters/12")
    assert missing.status_code == 404 and "telegram counters" in missing.json()["detail"]


def _job_done(client: TestClient, job_id: str) -> dict[str, Any]:
    def finished() -> dict[str, Any] | None:
        job: dict[str, Any] = client.get(f"/api/jobs/{job_id}").json()
        return job if job["state"] != "running" else None
    return wait_for_value(finished, 120, "the read-all ends")


def test_second_sdo_channels_belong_to_their_nodes_and_a_scan_is_one_row(client: TestClient) -> None:
    """Issue 28 item 7: node 5's and node 12's SDO2 traffic (0x645/0x5C5, 0x64C/0x5CC, their profiles'
    sdo_channels) is theirs, not nodes 69 and 76 "not in session"; a scan's requests to ids that never answered are
    one row, not 123 nodes."""
    demo = "/api/sessions/demo-plant"
    for node in (5, 12):
        job = client.post(f"{demo}/nodes/{node}/read-all").json()
        _job_done(client, job["id"])
    assert client.post(f"{demo}/scan", json={"timeout_s": 0.3}).status_code == 200
    snapshot = client.get(f"{demo}/monitor").json()
    by_cob = {row["cob_id"]: row for row in snapshot["cob_ids"]}
    assert {0x645, 0x5C5, 0x64C, 0x5CC} <= set(by_cob), "the read-all used the second SDO channels"
    assert [by_cob[cob]["node"] for cob in (0x645, 0x5C5, 0x64C, 0x5CC)] == [5, 5, 12, 12]
    listed = [row["node"] for row in snapshot["nodes"]]
    assert 69 not in listed and 76 not in listed
    assert {3, 5, 7, 12} <= {node for node in listed if node is not None}
    assert len(listed) <= 5, listed
    scan = snapshot["nodes"][-1]
    assert scan["node"] is None and scan["unanswered_ids"] >= 100 and scan["total"] >= scan["unanswered_ids"]
    trace = client.get(f"{demo}/monitor/trace", params={"limit": 10000}).json()["rows"]
    sdo2 = [row for row in trace if row["cob_id"] in ("0x5C5", "0x645")]
    assert sdo2 and {row["node"] for row in sdo2} == {5}
