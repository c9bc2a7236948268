"""Issue 31: a recording sampled by PDO ends where it was stopped. Through the real HTTP API on the demo plant (the
CiA 402 servo, node 7, at 10 ms): the stored free-run recording holds a sample for every SYNC a second python-can
bus saw on the plant's virtual channel, up to the last one sent before Stop, and the TPDO answers to the last SYNCs
(the ~50 ms the source waits for late frames) are kept, not dropped."""

from __future__ import annotations

import threading

import can
from fastapi.testclient import TestClient

from drivebench.services.scope import runs
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, wait_until
from tests.pdo_settings import tpdo_and_sync_settings

AXIS = 7
API = "/api/sessions/demo-plant"
SYNC = 0x080
BODY = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x6041"}], "period_ms": 10,
        "length_s": 100.0, "trigger": {"mode": "free"}, "name": "stopped here"}


class SyncCount(can.Listener):
    def __init__(self) -> None:
        self.count = 0
        self.lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == SYNC and not msg.is_error_frame:
            with self.lock:
                self.count += 1


def test_the_stored_recording_holds_every_sync_sent_before_stop(app_db_url: str) -> None:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    syncs = SyncCount()
    with TestClient(app) as client, can.Bus(interface="virtual", channel=channel) as wire:
        notifier = can.Notifier(wire, [syncs])
        try:
            started = confirmed(client, "POST", f"{API}/scope/run", json=BODY)
            assert started.status_code == 201 and started.json()["source"] == "pdo", started.text
            run = runs.current(client.app.state.drivebench.manager.get("demo-plant"))  # type: ignore[attr-defined]
            assert wait_until(lambda: sum(row[2] is not None for row in list(run.live)) >= 20, 30)
            stopped = client.post(f"{API}/scope/run/stop").json()
            assert stopped["state"] == "stopped" and stopped["recording_id"], stopped
            sent = int(stopped["restored"][0].split(":")[1].split()[0])  # "SYNC: 123 sent at a mean period ..."
            assert wait_until(lambda: syncs.count >= sent, 10), (syncs.count, sent)
            stored = client.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
        finally:
            notifier.stop()
    assert syncs.count == sent, "the producer's count is what the bus saw"
    assert stored["samples"] == list(range(sent)), (stored["samples"][-8:], sent)
    last = stored["values"][0][-5:]
    assert any(value is not None for value in last), f"the answers to the last SYNCs before Stop are kept: {last}"


def _tpdo_settings(client: TestClient) -> dict[str, object]:
    return tpdo_and_sync_settings(client, f"{API}/nodes/{AXIS}")


def test_a_recording_started_over_the_api_and_left_ends_by_itself_after_max_s_and_restores(
        demo_api: TestClient) -> None:
    before = _tpdo_settings(demo_api)
    started = confirmed(demo_api, "POST", f"{API}/scope/run", json={**BODY, "max_s": 2})
    assert started.status_code == 201 and started.json()["max_s"] == 2, started.text
    assert wait_until(lambda: demo_api.get(f"{API}/scope/run").json()["state"] == "stopped", 60)
    ended = demo_api.get(f"{API}/scope/run").json()
    assert "reached its maximum length of 2 s (max_s, set at start)" in ended["restored"][0], ended["restored"]
    assert any("read back as before" in text for text in ended["restored"]), ended["restored"]
    assert ended["recording_id"] and _tpdo_settings(demo_api) == before
    refused = demo_api.post(f"{API}/scope/run", json={**BODY, "max_s": 0})
    assert refused.status_code == 422 and refused.headers["content-type"] == "application/problem+json"


def test_a_page_of_the_owner_keeps_the_recording_past_max_s(demo_api: TestClient) -> None:
    started = confirmed(demo_api, "POST", f"{API}/scope/run", json={**BODY, "max_s": 1})
    assert started.status_code == 201, started.text
    with demo_api.websocket_connect("/ws/sessions/demo-plant/scope") as socket:  # the owner's page
        shown = 0
        while shown < 40:  # 40 batches of samples: several seconds, well past max_s
            message = socket.receive_json()
            shown += message["type"] == "rows"
            assert message.get("state") != "stopped", message
    assert demo_api.get(f"{API}/scope/run").json()["state"] == "recording", "the page kept it running"
    assert wait_until(lambda: demo_api.get(f"{API}/scope/run").json()["state"] == "stopped", 60), \
        "the page closed: the recording ends (after the reload grace)"
