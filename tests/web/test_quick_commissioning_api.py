"""The MICROMASTER's quick commissioning (issue 30 items 1-3) over the real HTTP API on the simulated demo plant:
a sequence of parameter steps from the profile (P0010 = 1 ... P3900), each taking the user's value or the
profile's proposal through the checked write (range, audit, lease, confirmation), read back; the simulated drive
refuses motor data outside quick commissioning with the seed manual's abort 0x08000022 and ends it on P3900; at
the end the motor turns when enabled over CANopen."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.node import SimulatedNode
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT

pytestmark = pytest.mark.usefixtures("patient_guard")  # flows, not the 2 s keep-alive deadline

DEMO = "demo-plant"
MM = 3
ANNA = {"X-DriveBench-User": "anna", "X-DriveBench-Client": "tab-anna"}
NAMEPLATE = {"P0100": 0, "P0300": 1, "P0304": 400, "P0305": 1.9, "P0307": 0.75, "P0308": 0.82, "P0309": 78.0,
             "P0310": 50.0, "P0311": 1395}
P1120_INDEX = 0x2000 + 1120


@pytest.fixture
def api(channel: str, app_db_url: str) -> Iterator[TestClient]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        yield client


def _url(tail: str) -> str:
    return f"/api/sessions/{DEMO}/nodes/{MM}{tail}"


def _sim(client: TestClient) -> SimulatedNode:
    sim: SimulatedNode = client.app.state.drivebench.plants[DEMO].nodes[MM]  # type: ignore[attr-defined]
    return sim


def _start(client: TestClient) -> dict[str, Any]:
    answer = client.post(_url("/control/sequences/mm-quick/runs"), headers=ANNA)
    assert answer.status_code == 201, answer.text
    run: dict[str, Any] = answer.json()
    return run


def _next(client: TestClient, run: dict[str, Any], value: object = None) -> Any:
    body = {} if value is None else {"value": value}
    return confirmed(client, "POST", _url(f"/control/runs/{run['id']}/next"), json=body, headers=ANNA)


def _downloads(wire: can.BusABC, index: int) -> list[can.Message]:
    seen = []
    while (msg := wire.recv(timeout=0)) is not None:
        if (msg.arbitration_id == 0x600 + MM and msg.data[0] & 0xE0 == 0x20
                and int.from_bytes(msg.data[1:3], "little") == index):
            seen.append(msg)
    return seen


def _run_to(client: TestClient, run: dict[str, Any], ref: str) -> dict[str, Any]:
    """Run the steps up to (not including) the one that sets ``ref``, with the nameplate or the proposals."""
    while True:
        step = run["steps"][run["position"]]
        if step["field"] and step["field"]["ref"] == ref:
            return run
        value = NAMEPLATE.get(step["field"]["ref"]) if step["field"] else None
        answer = _next(client, run, value)
        assert answer.status_code == 200, answer.text
        run = answer.json()
        assert run["failed"] is None, run["failed"]


def test_the_sequence_is_parameter_steps_with_the_profiles_ranges(api: TestClient) -> None:
    """Each step names its parameter and the form gets what the profile knows of it: unit, range, proposal and
    where the facts come from (P1120: 0 ... 650 s)."""
    keys = [seq["key"] for seq in api.get(_url("/control/sequences"), headers=ANNA).json()]
    assert "mm-quick" in keys
    run = _start(api)
    refs = [step["field"]["ref"] for step in run["steps"] if step["field"]]
    assert refs == ["P0010", "P0100", "P0300", "P0304", "P0305", "P0307", "P0308", "P0309", "P0310", "P0311",
                    "P0700", "P1000", "P1080", "P1082", "P1120", "P1121", "P3900"]
    p1120 = next(step["field"] for step in run["steps"] if step["field"] and step["field"]["ref"] == "P1120")
    assert (p1120["unit"], p1120["min"], p1120["max"], p1120["proposal"]) == ("s", 0.0, 650.0, 10.0)
    assert p1120["source"] and "650" in p1120["source"]
    assert run["steps"][0]["field"]["proposal"] == 1


def test_p1120_9999_and_minus_1_are_refused_with_the_range_and_nothing_is_sent(api: TestClient,
                                                                             wire: can.BusABC) -> None:
    run = _run_to(api, _start(api), "P1120")
    _downloads(wire, P1120_INDEX)
    for bad in (9999, -1):
        answer = _next(api, run, bad)
        assert answer.status_code == 422, answer.text
        assert "650" in answer.json()["detail"] and "0" in answer.json()["detail"]
        assert _downloads(wire, P1120_INDEX) == []
    run = api.get(_url(f"/control/runs/{run['id']}"), headers=ANNA).json()
    assert run["steps"][run["position"]]["field"]["ref"] == "P1120"  # the run stays at the step
    assert _next(api, run, 12.5).status_code == 200
    assert _sim(api).store.get_ref("P1120") == pytest.approx(12.5)


def test_the_parameters_tab_refuses_p1120_9999_too(api: TestClient) -> None:
    answer = api.put(_url("/parameters/P1120"), json={"value": 9999}, headers=ANNA)
    assert answer.status_code == 422, answer.text
    assert "650" in answer.json()["detail"]


def test_motor_data_are_refused_by_the_drive_outside_quick_commissioning(api: TestClient) -> None:
    """The simulated MICROMASTER answers 0x08000022 for P0304 while P0010 = 0 (seed manual's abort table)."""
    answer = api.put(_url("/parameters/P0304"), json={"value": 400}, headers=ANNA)
    assert answer.status_code == 502, answer.text
    assert answer.json()["abort_code"] == "0x08000022"
    assert _sim(api).store.get_ref("P0304") == 0


def test_quick_commissioning_from_p0010_to_p3900_then_the_motor_turns(api: TestClient) -> None:
    """The whole run with the nameplate values and the proposals: every write read back and in the audit log with
    the origin commissioning; P3900 sets P0010 back to 0; then enabled over CANopen the motor turns."""
    run = _start(api)
    assert _sim(api).store.get_ref("P0700") == 2  # terminals: an enable would do nothing
    while not run["finished"]:
        step = run["steps"][run["position"]]
        value = NAMEPLATE.get(step["field"]["ref"]) if step["field"] else None
        answer = _next(api, run, value)
        assert answer.status_code == 200, answer.text
        run = answer.json()
        assert run["failed"] is None, run["failed"]
        assert run["results"][-1]["ok"], run["results"][-1]
    sim = _sim(api)
    assert sim.store.get_ref("P0010") == 0 and sim.store.get_ref("P3900") == 3
    assert sim.store.get_ref("P0305") == pytest.approx(1.9) and sim.store.get_ref("P0311") == 1395
    assert (sim.store.get_ref("P0700"), sim.store.get_ref("P1000")) == (6, 6)
    rows = api.get("/api/audit", params={"node_id": MM}, headers=ANNA).json()
    written = {row["ref"] for row in rows if row.get("origin") == "commissioning"}
    assert {"P0010", "P0304", "P1120", "P3900"} <= written

    for command in ("shutdown", "enable_operation"):
        answer = confirmed(api, "POST", _url(f"/control/commands/{command}"), headers=ANNA)
        assert answer.status_code == 200, answer.text
    answer = confirmed(api, "PUT", _url("/control/setpoint"), json={"value": 600}, headers=ANNA)
    assert answer.status_code == 200, answer.text
    deadline = time.monotonic() + 20
    while sim.drive.speed_rpm <= 0 and time.monotonic() < deadline:  # type: ignore[union-attr]
        api.post(_url("/control/keepalive"), headers=ANNA)
        time.sleep(0.2)
    assert sim.drive.speed_rpm > 0  # type: ignore[union-attr]


def test_a_reload_finds_the_run_where_it_stands(api: TestClient) -> None:
    run = _run_to(api, _start(api), "P0304")
    listed = api.get(_url("/control/runs"), headers=ANNA)
    assert listed.status_code == 200, listed.text
    latest = listed.json()[0]
    assert latest["id"] == run["id"] and latest["position"] == run["position"]
    assert latest["steps"][latest["position"]]["field"]["ref"] == "P0304"
    empty = _next(api, latest)  # a nameplate value has no proposal: the user must give it
    assert empty.status_code == 422 and "needs a value" in empty.json()["detail"], empty.text
