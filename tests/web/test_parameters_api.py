"""The parameters REST API end to end: the manuals' SDO examples on the wire, problem+json for every abort, jobs.

The vectors (tests/vectors/manual_sdo.py) name the nodes the manuals use, so each manual gets its own plant:
8400 motec section 9.3 (nodes 2, 4, 5, 12) and EMF2178IB section 10.5 (8200 vector at nodes 1 and 5).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.web.app import create_app
from tests.conftest import wait_for_value
from tests.vectors.manual_sdo import LENZE_8400, LENZE_EMF2178IB, SdoVector

PLANTS: dict[str, list[dict[str, Any]]] = {
    "8400": [{"node_id": n, "profile": "lenze-8400-motec-canopen", "values": {"C00061": 43}} for n in (2, 4, 5, 12)],
    "emf": [{"node_id": n, "profile": "lenze-8200-vector-emf2178ib"} for n in (1, 5)],
}
SESSION = "api-plant"


class Api:
    def __init__(self, client: TestClient, wire: can.BusABC) -> None:
        self.client = client
        self.wire = wire

    def url(self, node: int, tail: str = "") -> str:
        return f"/api/sessions/{SESSION}/nodes/{node}{tail}"

    def drain(self) -> list[can.Message]:
        found = []
        while (msg := self.wire.recv(timeout=0.05)) is not None:
            found.append(msg)
        return found


def _start(tmp_path: Path, channel: str, nodes: list[dict[str, Any]]) -> Iterator[Api]:
    plant = tmp_path / "plant.json"
    plant.write_text(json.dumps({"name": "API plant", "nodes": nodes}), encoding="utf-8")
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    app = create_app(plant_file=plant, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    try:
        with TestClient(app) as client:
            yield Api(client, wire)
    finally:
        wire.shutdown()


@pytest.fixture
def api_8400(tmp_path: Path, channel: str) -> Iterator[Api]:
    yield from _start(tmp_path, channel, PLANTS["8400"])


@pytest.fixture
def api_emf(tmp_path: Path, channel: str) -> Iterator[Api]:
    yield from _start(tmp_path, channel, PLANTS["emf"])


def _ref_for(api: Api, vector: SdoVector) -> str:
    """Find the parameter by its index through the search API, as a user would."""
    found = api.client.get(api.url(vector.node, "/parameters"), params={"q": f"0x{vector.index:04X}"}).json()
    matches = [p for p in found["parameters"] if p["index"] == f"0x{vector.index:04X}" and
               p["subindex"] == vector.subindex]
    assert matches, f"0x{vector.index:04X}sub{vector.subindex} not found by search"
    return str(matches[0]["ref"])


def _assert_on_wire(frames: list[can.Message], vector: SdoVector) -> None:
    sdo = [(m.arbitration_id, bytes(m.data)) for m in frames if m.arbitration_id in
           (0x600 + vector.node, 0x580 + vector.node)]
    position = 0
    for request, response in vector.exchanges:
        for expected in (request, response):
            while position < len(sdo) and not expected.matches(*sdo[position]):
                position += 1
            assert position < len(sdo), f"{vector.id}: {expected} not on the wire in order"
            position += 1


def _replay(api: Api, vector: SdoVector) -> dict[str, Any]:
    ref = _ref_for(api, vector)
    api.drain()
    if vector.direction == "upload":
        response = api.client.get(api.url(vector.node, f"/parameters/{ref}"))
    else:
        response = api.client.put(api.url(vector.node, f"/parameters/{ref}"),
                                  json={"raw": int.from_bytes(vector.value, "little")})
    assert response.status_code == 200, response.text
    _assert_on_wire(api.drain(), vector)
    body: dict[str, Any] = response.json()
    return body


@pytest.mark.parametrize("vector", LENZE_8400, ids=lambda v: v.id)
def test_8400_motec_manual_examples(api_8400: Api, vector: SdoVector) -> None:
    body = _replay(api_8400, vector)
    if vector.direction == "upload":
        expected = vector.value.decode() if vector.index == 0x5F9C else int.from_bytes(vector.value, "little")
        assert body["raw"] == expected
    else:
        assert body["verified"] is True
        assert body["written"]["raw"] == int.from_bytes(vector.value, "little")


def test_8400_examples_scaled(api_8400: Api) -> None:
    c00061 = api_8400.client.get(api_8400.url(5, "/parameters/C00061")).json()
    assert {k: c00061[k] for k in ("raw", "value", "unit", "text")} == {"raw": 43, "value": 43, "unit": "°C",
                                                                       "text": None}
    written = api_8400.client.put(api_8400.url(2, "/parameters/C00088"), json={"value": "10.20 A"}).json()
    assert written["written"] == {"raw": 1020, "value": 10.2, "unit": "A", "text": None}
    assert written["read_back"]["display"] == "10.20 A"
    assert api_8400.client.get(api_8400.url(12, "/parameters/C00099")).json()["value"] == "01.00.00.00"
    assert api_8400.client.get(api_8400.url(5, "/parameters/C00351")).json()["text"] == "500 kbit/s"


@pytest.mark.parametrize("vector", LENZE_EMF2178IB, ids=lambda v: v.id)
def test_emf2178ib_manual_examples(api_emf: Api, vector: SdoVector) -> None:
    body = _replay(api_emf, vector)
    if vector.id == "emf-tv1-read-c0061":
        assert (body["raw"], body["value"], body["unit"]) == (430000, 43, "°C")
    elif vector.id == "emf-tv2-write-c0012":
        assert body["read_back"]["value"] == 20 and body["read_back"]["unit"] == "s"
    else:
        assert body["value"] == "82S8212V_14000"


# --- problem+json ------------------------------------------------------------------------------------------
def _problem(response: Any, status: int) -> dict[str, Any]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    body: dict[str, Any] = response.json()
    return body


@pytest.mark.parametrize(("method", "ref", "body", "status", "code"), [
    ("GET", "0x2FFF.0", None, 404, "0x06020000"),                            # unknown object
    ("GET", "0x1018.9", None, 404, "0x06090011"),                            # unknown subindex
    ("PUT", "C00061", {"value": 3, "check": False}, 422, "0x06010002"),      # read-only
    ("PUT", "C00350", {"value": 100, "check": False}, 422, "0x06090030"),    # range
])
def test_sdo_aborts_are_problems_with_code_and_text(api_8400: Api, method: str, ref: str, body: Any,
                                                     status: int, code: str) -> None:
    response = api_8400.client.request(method, api_8400.url(5, f"/parameters/{ref}"), json=body)
    problem = _problem(response, status)
    assert problem["abort_code"] == code and problem["abort_text"]
    assert problem["node"] == 5 and problem["object"].startswith("0x")
    assert code in problem["detail"]


def test_validation_problems_name_parameter_range_and_unit(api_8400: Api) -> None:
    problem = _problem(api_8400.client.put(api_8400.url(5, "/parameters/C00350"), json={"value": 100}), 422)
    assert "C00350" in problem["detail"] and "1 ... 63" in problem["detail"] and "abort_code" not in problem
    problem = _problem(api_8400.client.put(api_8400.url(5, "/parameters/C00088"), json={"value": 1e9}), 422)
    assert "C00088" in problem["detail"] and "UNSIGNED32" in problem["detail"]
    problem = _problem(api_8400.client.put(api_8400.url(5, "/parameters/C00061"), json={"value": 1}), 422)
    assert problem["title"] == "Parameter is read-only"
    problem = _problem(api_8400.client.get(api_8400.url(5, "/parameters/C09999")), 404)
    assert problem["title"] == "Unknown parameter"
    assert api_8400.client.put(api_8400.url(5, "/parameters/C00088"), json={}).status_code == 422


def test_absent_node_is_a_timeout_problem(api_8400: Api) -> None:
    assert api_8400.client.post(f"/api/sessions/{SESSION}/nodes",
                                json={"node_id": 40, "profile_id": "lenze-8400-motec-canopen"}).status_code < 300
    problem = _problem(api_8400.client.get(api_8400.url(40, "/parameters/C00061")), 504)
    assert problem["node"] == 40 and problem["object"] == "0x5FC2sub0"


def test_slow_node_times_out_with_the_session_timeout(api_8400: Api) -> None:
    """A node that is there but answers after the session's SDO timeout: 504, and the other nodes still answer."""
    from drivebench.simulator.node import Latency

    assert api_8400.client.put(f"/api/sessions/{SESSION}/sdo-settings",
                               json={"timeout_s": 0.3, "retries": 0}).status_code == 200
    api_8400.client.app.state.drivebench.plants[SESSION].nodes[4].latency = Latency(1.0)  # type: ignore[attr-defined]
    problem = _problem(api_8400.client.get(api_8400.url(4, "/parameters/C00088")), 504)
    assert problem["node"] == 4 and problem["object"] == "0x5FA7sub0" and "did not answer" in problem["detail"]
    assert api_8400.client.get(api_8400.url(5, "/parameters/C00088")).json()["display"] == "10.20 A"


def test_write_verify_reports_a_mismatch(api_8400: Api) -> None:
    """The device keeps C00088 in 0.1 A steps: the write succeeds, the read-back differs and the answer says so."""
    store = api_8400.client.app.state.drivebench.plants[SESSION].nodes[5].store  # type: ignore[attr-defined]
    store.add_write_hook(lambda index, sub, raw: store.set(index, sub, raw // 10 * 10, notify=False)
                         if (index, sub) == (0x5FA7, 0) else None)
    body = api_8400.client.put(api_8400.url(5, "/parameters/C00088"), json={"value": "12.34 A"}).json()
    assert body["verified"] is False and body["written"]["raw"] == 1234 and body["read_back"]["raw"] == 1230
    assert body["mismatch"] == "Wrote 12.34 A, the device reports 12.30 A"
    assert api_8400.client.put(api_8400.url(5, "/parameters/C00088"), json={"value": 12.3}).json()["verified"]


# --- list, search, jobs, commands ---------------------------------------------------------------------------
def test_list_and_search(api_8400: Api) -> None:
    listing = api_8400.client.get(api_8400.url(5, "/parameters")).json()
    assert listing["groups"][0] == "Device commands" and len(listing["parameters"]) > 100
    for query, ref in [("C00088", "C00088"), ("88", "C00088"), ("rated motor current", "C00088"),
                       ("0x5FA7", "C00088"), ("5FA7sub0", "C00088")]:
        found = api_8400.client.get(api_8400.url(5, "/parameters"), params={"q": query}).json()["parameters"]
        assert found and found[0]["ref"] == ref, query
    group = api_8400.client.get(api_8400.url(5, "/parameters"), params={"group": "Motor data"}).json()
    assert {p["group"] for p in group["parameters"]} == {"Motor data"}


def _wait_job(api: Api, job_id: str) -> dict[str, Any]:
    def finished() -> dict[str, Any] | None:
        job: dict[str, Any] = api.client.get(f"/api/jobs/{job_id}").json()
        return job if job["state"] != "running" else None
    done: dict[str, Any] = wait_for_value(finished, 60, f"job {job_id} to finish")
    return done


def test_read_all_job_with_progress_stream(api_8400: Api) -> None:
    started = api_8400.client.post(api_8400.url(5, "/read-all"))
    assert started.status_code == 202
    job = started.json()
    messages = []
    with api_8400.client.websocket_connect(job["links"]["progress"]) as socket:
        while True:
            messages.append(socket.receive_json())
            if messages[-1]["state"] != "running":
                break
    assert messages[-1]["state"] == "done"
    assert messages[-1]["progress"]["done"] == messages[-1]["progress"]["total"] == job["progress"]["total"]
    fields = {"done", "total", "failed", "not_done", "rate_per_s", "eta_s", "elapsed_s"}  # the API and the socket
    assert set(job["progress"]) == set(messages[-1]["progress"]) == fields and messages[-1]["progress"]["eta_s"] is None
    schema = api_8400.client.get("/openapi.json").json()["components"]["schemas"]
    assert set(schema["Progress"]["properties"]) == fields and "ProgressOut" not in schema
    final = _wait_job(api_8400, job["id"])
    assert final["result"]["values"]["5"]["C00088"]["display"] == "10.20 A"
    listing = api_8400.client.get(api_8400.url(5, "/parameters"), params={"q": "C00061"}).json()
    assert listing["parameters"][0]["last"]["value"] == 43
    assert api_8400.client.delete(f"/api/jobs/{job['id']}").status_code == 409


def test_the_same_read_asked_again_follows_the_running_job(api_8400: Api) -> None:
    first = api_8400.client.post(api_8400.url(5, "/read-all")).json()
    again = [api_8400.client.post(api_8400.url(5, "/read-all")).json() for _ in range(5)]
    assert {job["id"] for job in again} == {first["id"]}, "no read queues up behind a running one of the same node"
    assert _wait_job(api_8400, first["id"])["state"] == "done"
    after = api_8400.client.post(api_8400.url(5, "/read-all")).json()
    assert after["id"] != first["id"], "a finished read does not stand for a new one"
    _wait_job(api_8400, after["id"])


def test_read_all_nodes_of_a_session_and_group_read(api_8400: Api) -> None:
    job = api_8400.client.post(f"/api/sessions/{SESSION}/read-all", json={}).json()
    final = _wait_job(api_8400, job["id"])
    assert final["state"] == "done" and set(final["result"]["values"]) == {"2", "4", "5", "12"}
    group = api_8400.client.post(api_8400.url(5, "/read-group"), json={"group": "Motor data"}).json()
    final = _wait_job(api_8400, group["id"])
    assert "C00088" in final["result"]["values"]["5"]
    assert api_8400.client.post(api_8400.url(5, "/read-group"), json={"group": "Nope"}).status_code == 404
    assert api_8400.client.get("/api/jobs/nope").status_code == 404


def test_device_commands_and_reset_required(api_8400: Api) -> None:
    written = api_8400.client.put(api_8400.url(5, "/parameters/C00351"), json={"value": "250 kbit/s"}).json()
    assert written["reset_required"] and written["pending_reset"] == ["C00351"]
    saved = api_8400.client.post(api_8400.url(5, "/commands/save")).json()
    assert saved["via"] == "C00002/11 = 1" and saved["pending_reset"] == ["C00351"]
    reset = api_8400.client.post(api_8400.url(5, "/commands/reset-node")).json()
    assert reset["pending_reset"] == []
    assert api_8400.client.post(api_8400.url(5, "/commands/explode")).status_code == 422


def test_sdo_settings_per_session(api_8400: Api) -> None:
    assert api_8400.client.put(f"/api/sessions/{SESSION}/sdo-settings",
                               json={"timeout_s": 0.1, "retries": 0, "use_sdo2": False}).status_code == 200
    assert api_8400.client.get(f"/api/sessions/{SESSION}/sdo-settings").json() == {
        "timeout_s": 0.1, "retries": 0, "use_sdo2": False}
    assert api_8400.client.put(f"/api/sessions/{SESSION}/sdo-settings",
                               json={"timeout_s": 0, "retries": 0}).status_code == 422


def test_string_by_block_upload(api_8400: Api) -> None:
    """C00099 (firmware version, VISIBLE_STRING) by CiA 301 block upload: initiate 0xA0 ... end 0xA1 on the wire."""
    api_8400.drain()
    value = api_8400.client.get(api_8400.url(5, "/parameters/C00099"), params={"transfer": "block"})
    assert value.status_code == 200, value.text
    assert value.json()["value"] == "01.00.00.00"
    requests = [m.data[0] for m in api_8400.drain() if m.arbitration_id == 0x605]
    assert requests[0] & 0xE3 == 0xA0 and requests[-1] == 0xA1
    refused = api_8400.client.get(api_8400.url(5, "/parameters/C00099"), params={"transfer": "fast"})
    assert refused.status_code == 422


def test_block_upload_refused_where_the_device_has_none(api_emf: Api) -> None:
    refused = api_emf.client.get(api_emf.url(5, "/parameters/C0200"), params={"transfer": "block"})
    assert refused.status_code == 422, refused.text
    assert "block transfer" in refused.json()["detail"]


def test_parameters_tab_shows_the_chosen_parameter_set(api_emf: Api) -> None:
    """EMF2178IB §10.2.1: the 8200 vector's four parameter sets are addressed directly (C2012 = C0012 in set 2,
    index 0x5823, §10.3). The Parameters tab offers the sets and shows such codes as "C0012 · set 2"."""
    ui = f"/ui/sessions/{SESSION}/nodes/1/parameters"
    first = api_emf.client.get(ui, params={"q": "acceleration time"}).text
    assert 'data-ref="C0012"' in first and "· set" not in first
    page = api_emf.client.get(f"/sessions/{SESSION}/nodes/1").text
    assert 'id="param-set"' in page and ">Parameter set 4</option>" in page
    second = api_emf.client.get(ui, params={"q": "acceleration time", "pset": 2}).text
    assert 'data-ref="C2012"' in second and ">C0012 · set 2</td>" in second and ">5823.0</td>" in second
    written = api_emf.client.post(f"{ui}/C2012/write", data={"value": "20"})
    assert written.status_code == 200 and "verified" in written.text
    assert api_emf.client.get(api_emf.url(1, "/parameters/C2012")).json()["value"] == 20
    assert api_emf.client.get(api_emf.url(1, "/parameters/C0012")).json()["value"] != 20  # set 1 keeps its own
    listed = api_emf.client.get(api_emf.url(1, "/parameters"), params={"q": "C0012", "parameter_set": 2}).json()
    assert [(p["ref"], p["index"]) for p in listed["parameters"]][:1] == [("C2012", "0x5823")]
    rows = api_emf.client.get(ui, params={"pset": 3}).text
    assert ">C0011 · set 3</td>" in rows and ">C0001 · set 3</td>" in rows and 'data-ref="C0046"' in rows
