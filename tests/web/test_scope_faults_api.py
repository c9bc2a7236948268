"""Issue 31 item 6, the faults the PDO part of a recording reports in words, through the real HTTP API on the demo
plant (the CiA 402 servo, node 7, sampled by PDO at 10 ms): the CAN controller going bus-off (the virtual bus's
adapter reports it; nothing is sent or received) and SYNC lost (the adapter unplugged: DriveBench cannot send SYNC)
are markers of the stored recording, and Stop after the bus is back restores the TPDO; a TPDO set-up that the
device refuses halfway is put back at once, in words, never called "remapped by someone else", and leaves no
restore record behind."""

from __future__ import annotations

from typing import Any

import can
from fastapi.testclient import TestClient

from drivebench.services.bus.sessions import Session
from drivebench.services.scope import restore_record, runs
from drivebench.simulator.store import Abort
from drivebench.transport.bus import SimulatedAdapter
from tests.confirming import confirmed
from tests.conftest import wait_until
from tests.pdo_settings import tpdo_and_sync_settings

AXIS = 7
API = "/api/sessions/demo-plant"
BODY: dict[str, Any] = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x6041"}],
                        "period_ms": 10, "length_s": 100.0, "trigger": {"mode": "free"}, "name": "faults"}


def _session(client: TestClient) -> Session:
    return client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined,no-any-return]


def _adapter(client: TestClient) -> SimulatedAdapter:
    adapter = _session(client).network.bus.adapter
    assert adapter is not None, "a virtual bus has a simulated adapter"
    return adapter


def _tpdo_settings(client: TestClient) -> dict[str, object]:
    return tpdo_and_sync_settings(client, f"{API}/nodes/{AXIS}")


def _start_and_wait_for_samples(client: TestClient) -> None:
    """Started over the API with no page open (a page closing would end the recording)."""
    started = confirmed(client, "POST", f"{API}/scope/run", json=BODY)
    assert started.status_code == 201, started.text
    assert started.json()["source"] == "pdo", started.json()
    run = runs.current(_session(client))
    assert wait_until(lambda: sum(row[2] is not None for row in list(run.live)) >= 5, 30), list(run.live)[-5:]


def _markers_after_stop(client: TestClient) -> tuple[dict[str, Any], list[str]]:
    stopped = client.post(f"{API}/scope/run/stop").json()
    assert stopped["state"] == "stopped" and stopped["recording_id"], stopped
    stored = client.get(f"/api/scope/recordings/{stopped['recording_id']}").json()
    return stopped, [m["text"] for m in stored["markers"] if m["kind"] == "source"]


def _run_events(client: TestClient) -> list[Any]:
    """The source's events of the running recording (its markers while it runs)."""
    return [e for e in runs.current(_session(client)).events if e.kind == "source"]


def test_bus_off_and_the_sync_it_cannot_send_are_markers_and_stop_restores_once_the_bus_is_back(
        demo_api: TestClient) -> None:
    before = _tpdo_settings(demo_api)
    _start_and_wait_for_samples(demo_api)
    adapter = _adapter(demo_api)
    adapter.report(can.BusState.ERROR)  # bus-off: the controller left the bus
    assert wait_until(lambda: any("bus-off" in e.text for e in _run_events(demo_api)), 30), _run_events(demo_api)
    assert wait_until(lambda: any("SYNC lost" in e.text for e in _run_events(demo_api)), 30), _run_events(demo_api)
    adapter.report(can.BusState.ACTIVE)  # recovered
    stopped, markers = _markers_after_stop(demo_api)
    assert any("The CAN adapter is bus-off" in text for text in markers), markers
    assert any(text.startswith("SYNC lost: DriveBench could not send it") for text in markers), markers
    assert any("read back as before" in text for text in stopped["restored"]), stopped["restored"]
    assert _tpdo_settings(demo_api) == before


def test_sync_lost_when_the_adapter_is_unplugged_is_a_marker_without_bus_off(demo_api: TestClient) -> None:
    before = _tpdo_settings(demo_api)
    _start_and_wait_for_samples(demo_api)
    adapter = _adapter(demo_api)
    adapter.unplug("pulled for the test")
    assert wait_until(lambda: any("SYNC lost" in e.text for e in _run_events(demo_api)), 30), _run_events(demo_api)
    adapter.plug_in()
    assert wait_until(lambda: _session(demo_api).bus_state == "active", 30), _session(demo_api).bus_state
    assert wait_until(lambda: demo_api.get(f"{API}/nodes/{AXIS}/parameters/0x1000").status_code == 200, 30), \
        "the node answers again once the adapter is back"
    stopped, markers = _markers_after_stop(demo_api)
    assert [text for text in markers if text.startswith("SYNC lost")], markers
    assert not any("bus-off" in text for text in markers), markers
    assert _tpdo_settings(demo_api) == before, stopped["restored"]


def test_a_tpdo_set_up_refused_halfway_is_put_back_at_once_and_not_called_someone_elses(
        demo_api: TestClient, app_db_url: str) -> None:
    before = _tpdo_settings(demo_api)
    store = demo_api.app.state.drivebench.plants["demo-plant"].nodes[AXIS].store  # type: ignore[attr-defined]
    refused: list[tuple[int, int]] = []

    def refuse_second_entry_once(index: int, sub: int, raw: object) -> None:
        if 0x1A00 <= index <= 0x1BFF and sub == 2 and not refused:  # the device takes entry 1, not entry 2
            refused.append((index, sub))
            raise Abort(0x06040041)  # object cannot be mapped to the PDO

    store.add_write_check(refuse_second_entry_once)
    answer = confirmed(demo_api, "POST", f"{API}/scope/run", json=BODY)
    assert refused, "the recording's set-up reached the second mapping entry"
    assert answer.status_code == 409 and answer.headers["content-type"] == "application/problem+json"
    detail = answer.json()["detail"]
    assert "could not be set up for the recording" in detail, detail
    assert "restored and read back as before" in detail, detail
    assert "someone else" not in detail and "restore record is kept" not in detail, detail
    assert restore_record.leftovers(app_db_url) == [], "nothing left for the next server start"
    assert _tpdo_settings(demo_api) == before
    assert demo_api.get(f"{API}/scope/run").status_code == 404, "no recording runs"
