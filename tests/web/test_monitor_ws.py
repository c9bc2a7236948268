"""The monitor websocket: a client gets the hello (history, trace) and then counter updates that move."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.web.app import create_app
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
            if update["snapshot"]["totals"]["frames"] > first_total + 10 and heartbeat_rows:
                break
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


def test_two_clients_share_one_feed(monitor_client: TestClient) -> None:
    url = f"/ws/sessions/{SESSION_ID}/monitor"
    with monitor_client.websocket_connect(url) as first, monitor_client.websocket_connect(url) as second:
        assert json.loads(first.receive_text())["type"] == "hello"
        assert json.loads(second.receive_text())["type"] == "hello"
        seqs_first = [json.loads(first.receive_text())["seq"] for _ in range(3)]
        seqs_second = [json.loads(second.receive_text())["seq"] for _ in range(3)]
        assert seqs_first == sorted(seqs_first) and seqs_second == sorted(seqs_second)
