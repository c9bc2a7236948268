"""The monitor websocket: a client gets the hello (history, trace) and then counter updates that move."""

from __future__ import annotations

import asyncio
import gc
import json
import logging
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.web.app import create_app
from tests.conftest import wait_until
from tests.web.monitor_plant import SESSION_ID, write_plant


@pytest.fixture
def monitor_client(tmp_path: Path, channel: str) -> Iterator[TestClient]:
    app = create_app(plant_file=write_plant(tmp_path), plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as test_client:
        yield test_client


def test_client_receives_counter_updates(monitor_client: TestClient) -> None:
    with monitor_client.websocket_connect(f"/ws/sessions/{SESSION_ID}/monitor") as socket:
        hello: dict[str, Any] = json.loads(socket.receive_text())
        assert hello["type"] == "hello"
        assert {"snapshot", "history", "trace", "trace_more", "recording", "server_time", "seq"} <= hello.keys()
        first_total = hello["snapshot"]["totals"]["frames"]
        deadline = time.monotonic() + 15
        heartbeat_rows: list[dict[str, Any]] = []
        update: dict[str, Any] = {}
        while time.monotonic() < deadline:
            update = json.loads(socket.receive_text())
            assert update["type"] == "update"
            rows = [dict(zip(update["trace_columns"], row, strict=True)) for row in update["trace"]]
            heartbeat_rows += [row for row in rows if row["service"] == "Heartbeat"]
            heartbeat_rate = sum(row["rate"] for row in update["snapshot"]["services"] if row["service"] == "Heartbeat")
            if update["snapshot"]["totals"]["frames"] > first_total + 10 and heartbeat_rows and heartbeat_rate:
                break  # rates are of closed one-second windows: the first comes a second after the start
        assert update["snapshot"]["totals"]["frames"] > first_total + 10, "counters did not move"
        last = heartbeat_rows[-1]
        assert (last["cob_id"], last["node"], last["summary"]) in (("0x705", 5, "Pre-operational"),
                                                                   ("0x70C", 12, "Pre-operational"))
        # COB-ID rows travel as arrays in the order of cob_columns.
        columns = update["snapshot"]["cob_columns"]
        cobs = {row[columns.index("text")]: dict(zip(columns, row, strict=True))
                for row in update["snapshot"]["cob_ids"]}
        assert cobs["0x705"]["service"] == "Heartbeat" and cobs["0x705"]["node"] == 5 and cobs["0x705"]["total"] > 0
        services = {row["service"]: row for row in update["snapshot"]["services"]}
        assert services["Heartbeat"]["total"] > 0 and services["Heartbeat"]["rate"] > 0
        nodes = {row["node"]: row for row in update["snapshot"]["nodes"]}
        assert nodes[5]["name"] == "Conveyor (8400 motec)"


def test_unknown_session_closes_with_4404(monitor_client: TestClient) -> None:
    from starlette.websockets import WebSocketDisconnect

    with pytest.raises(WebSocketDisconnect) as closed, \
            monitor_client.websocket_connect("/ws/sessions/nope/monitor") as socket:
        socket.receive_text()
    assert closed.value.code == 4404


def test_a_client_closing_leaves_no_unread_task_exception(monitor_client: TestClient,
                                                           caplog: pytest.LogCaptureFixture) -> None:
    """A client that closes ends the socket's reader quietly and its handler waits for it: no "Task exception was
    never retrieved ... WebSocketDisconnect(1000)" in the log (the old handler left the reader running when it was
    cancelled first, about one close in three)."""
    caplog.set_level(logging.ERROR, logger="asyncio")
    for _ in range(20):
        with monitor_client.websocket_connect(f"/ws/sessions/{SESSION_ID}/monitor") as socket:
            socket.receive_text()
    assert wait_until(lambda: not _socket_tasks(monitor_client), 30), "the sockets' tasks did not end"
    gc.collect()
    unread = [record.getMessage() for record in caplog.records if "never retrieved" in record.getMessage()]
    assert not unread, unread


def _socket_tasks(client: TestClient) -> list[str]:
    """The monitor sockets' reader and writer tasks still alive in the app's event loop."""
    async def alive() -> list[str]:
        return [name for task in asyncio.all_tasks() if not task.done()
                and (name := getattr(task.get_coro(), "__name__", "")) in ("_receive_views", "_send_loop")]
    return client.portal.call(alive)  # type: ignore[union-attr]


def test_hello_and_updates_carry_each_telegram_once(monitor_client: TestClient) -> None:
    """The hello's trace ends where the next update starts: sequence numbers run on without gap or repeat, also
    for a client that joins a feed already running for another."""
    url = f"/ws/sessions/{SESSION_ID}/monitor"
    with monitor_client.websocket_connect(url) as first:
        for _ in range(4):
            first.receive_text()
        _check_contiguous(monitor_client, url)
        _check_contiguous(monitor_client, url)


def _check_contiguous(monitor_client: TestClient, url: str) -> None:
    with monitor_client.websocket_connect(url) as socket:
        seqs: list[int] = []
        more = False
        deadline = time.monotonic() + 15
        while len(seqs) < 40 and time.monotonic() < deadline:
            message = json.loads(socket.receive_text())
            position = message["trace_columns"].index("seq")
            seqs += [row[position] for row in message["trace"]]
            more = more or message["trace_more"]
        assert len(seqs) >= 40, "too few telegrams"
        assert not more  # a few heartbeats a second fit in every update
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_two_clients_share_one_feed(monitor_client: TestClient) -> None:
    url = f"/ws/sessions/{SESSION_ID}/monitor"
    with monitor_client.websocket_connect(url) as first, monitor_client.websocket_connect(url) as second:
        assert json.loads(first.receive_text())["type"] == "hello"
        assert json.loads(second.receive_text())["type"] == "hello"
        seqs_first = [json.loads(first.receive_text())["seq"] for _ in range(3)]
        seqs_second = [json.loads(second.receive_text())["seq"] for _ in range(3)]
        assert seqs_first == sorted(seqs_first) and seqs_second == sorted(seqs_second)


# --- per-viewer filter and pause ---------------------------------------------------------------------------------
URL = f"/ws/sessions/{SESSION_ID}/monitor"
HEARTBEATS = {5: "0x705", 12: "0x70C"}


def _rows(message: dict[str, Any]) -> list[dict[str, Any]]:
    return [dict(zip(message["trace_columns"], row, strict=True)) for row in message["trace"]]


def _until(socket: Any, accept: Any, what: str, timeout_s: float = 15) -> dict[str, Any]:
    """The first message ``accept`` takes (earlier ones are skipped)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message: dict[str, Any] = json.loads(socket.receive_text())
        if accept(message):
            return message
    raise AssertionError(f"no {what} in {timeout_s} s")


def _heartbeat_view(node: int) -> str:
    return json.dumps({"type": "view", "filter": {"nodes": [node], "services": ["Heartbeat"]}})


def _collect_cobs(socket: Any, count: int) -> set[str]:
    cobs: list[str] = []
    deadline = time.monotonic() + 15
    while len(cobs) < count and time.monotonic() < deadline:
        message = json.loads(socket.receive_text())
        assert message["type"] == "update"
        cobs += [row["cob_id"] for row in _rows(message)]
    assert len(cobs) >= count, "too few telegrams"
    return set(cobs)


def test_each_client_has_its_own_filter(monitor_client: TestClient) -> None:
    with monitor_client.websocket_connect(URL) as first, monitor_client.websocket_connect(URL) as second:
        first.receive_text()
        second.receive_text()
        first.send_text(_heartbeat_view(5))
        second.send_text(_heartbeat_view(12))
        hello_first = _until(first, lambda m: m["type"] == "hello", "hello")
        hello_second = _until(second, lambda m: m["type"] == "hello", "hello")
        assert hello_first["view"]["filter"]["nodes"] == [5] and hello_second["view"]["filter"]["nodes"] == [12]
        # The hello's trace is already filtered (the newest matching rows of the shared ring).
        assert {row["cob_id"] for row in _rows(hello_first)} <= {"0x705"}
        assert {row["cob_id"] for row in _rows(hello_second)} <= {"0x70C"}
        assert _collect_cobs(first, 6) == {"0x705"}
        assert _collect_cobs(second, 3) == {"0x70C"}
        update = _until(second, lambda m: m["type"] == "update", "update")
        columns = update["snapshot"]["cob_columns"]
        assert {row[columns.index("text")] for row in update["snapshot"]["cob_ids"]} == {"0x70C"}
        assert [row["node"] for row in update["snapshot"]["nodes"]] == [12]
        # Counting is shared and unfiltered: both see every service.
        services = {row["service"]: row["total"] for row in update["snapshot"]["services"]}
        assert services["Heartbeat"] > 0
        # The REST default view is untouched by the clients' filters.
        assert monitor_client.get(f"/api/sessions/{SESSION_ID}/monitor/filter").json()["nodes"] == []


def test_pausing_one_client_does_not_pause_the_other(monitor_client: TestClient) -> None:
    with monitor_client.websocket_connect(URL) as first, monitor_client.websocket_connect(URL) as second:
        first.receive_text()
        second.receive_text()
        first.send_text(json.dumps({"type": "view", "paused": True}))
        answer = _until(first, lambda m: m["type"] != "update", "pause answer")
        assert answer == {"type": "view", "view": {"filter": answer["view"]["filter"], "paused": True}}
        # The other client goes on: counters move and heartbeats arrive.
        start = _until(second, lambda m: m["type"] == "update", "update")["snapshot"]["totals"]["frames"]
        moved = _until(second, lambda m: m["snapshot"]["totals"]["frames"] > start + 5, "moving counters")
        assert moved["type"] == "update" and moved["snapshot"]["paused"] is False
        assert monitor_client.get(f"/api/sessions/{SESSION_ID}/monitor").json()["paused"] is False
        # The paused client was sent nothing meanwhile: the first message after its resume is the resync hello.
        first.send_text(json.dumps({"type": "view", "paused": False}))
        resumed = json.loads(first.receive_text())
        assert resumed["type"] == "hello" and resumed["view"]["paused"] is False
        assert resumed["snapshot"]["totals"]["frames"] >= moved["snapshot"]["totals"]["frames"]
        assert _until(first, lambda m: m["type"] == "update", "update after resume")["snapshot"]["paused"] is False


def test_rest_filter_and_pause_are_the_defaults_for_new_viewers(monitor_client: TestClient) -> None:
    api = f"/api/sessions/{SESSION_ID}/monitor"
    with monitor_client.websocket_connect(URL) as earlier:
        earlier.receive_text()
        assert monitor_client.put(f"{api}/filter", json={"nodes": [12], "services": ["Heartbeat"]}).status_code == 200
        with monitor_client.websocket_connect(URL) as newer:
            hello = json.loads(newer.receive_text())
            assert hello["view"] == {"filter": {"nodes": [12], "services": ["Heartbeat"], "cob_min": 0,
                                                "cob_max": 0x1FFFFFFF}, "paused": False}
            assert _collect_cobs(newer, 3) == {"0x70C"}
        # A client connected before keeps its own (unfiltered) view.
        assert _collect_cobs(earlier, 8) >= {"0x705", "0x70C"}
        monitor_client.post(f"{api}/pause")
        with monitor_client.websocket_connect(URL) as paused:
            hello = json.loads(paused.receive_text())
            assert hello["view"]["paused"] is True and hello["snapshot"]["paused"] is True
        monitor_client.post(f"{api}/resume")


def test_bad_view_message_is_answered_with_an_error(monitor_client: TestClient) -> None:
    with monitor_client.websocket_connect(URL) as socket:
        socket.receive_text()
        socket.send_text(json.dumps({"type": "view", "filter": {"cob_min": 0x700, "cob_max": 0x100}}))
        error = _until(socket, lambda m: m["type"] == "error", "error answer")
        assert error["detail"] == "Filter not applied: cob_min must not be above cob_max"
        socket.send_text(json.dumps({"type": "view", "filter": {"nodes": [200]}}))
        error = _until(socket, lambda m: m["type"] == "error", "error answer")
        assert error["detail"] == "Filter not applied: nodes: Input should be less than or equal to 127"
        socket.send_text("not json")
        assert "Not a view message" in _until(socket, lambda m: m["type"] == "error", "error answer")["detail"]
        # The socket lives on with its view unchanged.
        assert _until(socket, lambda m: m["type"] == "update", "update")["snapshot"]["filter"]["nodes"] == []


def test_reset_sends_every_live_client_a_new_hello(monitor_client: TestClient) -> None:
    with monitor_client.websocket_connect(URL) as first, monitor_client.websocket_connect(URL) as second:
        first.receive_text()
        second.receive_text()
        second.send_text(_heartbeat_view(5))
        _until(second, lambda m: m["type"] == "hello", "hello")
        _until(first, lambda m: m["snapshot"]["totals"]["frames"] > 5, "frames")
        monitor_client.post(f"/api/sessions/{SESSION_ID}/monitor/reset")
        for socket, nodes in ((first, []), (second, [5])):
            hello = _until(socket, lambda m: m["type"] == "hello", "hello after the reset")
            assert hello["snapshot"]["totals"]["frames"] < 5 and hello["view"]["filter"]["nodes"] == nodes


def test_bus_state_travels_in_the_updates(monitor_client: TestClient, wire: Any) -> None:
    import can

    with monitor_client.websocket_connect(URL) as socket:
        hello = json.loads(socket.receive_text())
        assert hello["snapshot"]["bus"]["state"] == "active" and hello["snapshot"]["bus"]["tx_errors"] is None
        # SocketCAN error frame: controller problem (class 0x004), TX error passive, TEC 130, REC 7.
        wire.send(can.Message(arbitration_id=0x004, is_error_frame=True,
                              data=bytes([0, 0x20, 0, 0, 0, 0, 130, 7])))
        bus = _until(socket, lambda m: m["snapshot"]["bus"]["state"] != "active", "bus state")["snapshot"]["bus"]
        assert (bus["state"], bus["tx_errors"], bus["rx_errors"]) == ("passive", 130, 7)
        wire.send(can.Message(arbitration_id=0x040, is_error_frame=True, data=bytes(8)))
        _until(socket, lambda m: m["snapshot"]["bus"]["state"] == "bus-off", "bus-off")
        wire.send(can.Message(arbitration_id=0x100, is_error_frame=True, data=bytes(8)))
        _until(socket, lambda m: m["snapshot"]["bus"]["state"] == "active", "back to error active")
