"""Many viewers of one node's control panel (issue 27 item 7), through real websockets on a uvicorn server with the
demo plant on a real virtual bus: the node's status is polled once per period however many panels watch it."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import threading
from collections.abc import Coroutine, Iterator
from typing import Any

import can
import pytest
import websockets
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from drivebench.config import settings
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app, wait_until

NODE = 5
PERIODS = 8


@pytest.fixture
def served() -> Iterator[tuple[str, str]]:
    channel = fresh_channel()
    with serve_app(create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")) as url:
        yield url.replace("http", "ws", 1), channel


class RequestCounter(can.Listener):
    """SDO requests to the node seen on the wire (a python-can bus of its own on the plant's channel)."""

    def __init__(self) -> None:
        self.count = 0
        self.lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == 0x600 + NODE:
            with self.lock:
                self.count += 1


def _url(base: str, viewer: int) -> str:
    return f"{base}/ws/sessions/demo-plant/nodes/{NODE}/control?panel=viewer{viewer}&operator=v{viewer}"


async def _requests_per_period(base: str, counter: RequestCounter, viewers: int) -> float:
    """SDO requests to the node per status message, counted over PERIODS messages of the first viewer while
    ``viewers`` panels watch (each in the name of a user of its own, every second one in German)."""
    sockets = [await websockets.connect(_url(base, n), additional_headers={
        "X-DriveBench-User": f"user{n}", "Accept-Language": "de" if n % 2 else "en"},
        open_timeout=60)  # not websockets' 10 s: two suites on 2 cores timed out a handshake while the rest read
               for n in range(viewers)]
    try:
        first = sockets[0]

        async def status() -> None:
            while json.loads(await first.recv())["type"] != "status":
                pass

        async def drain(socket: websockets.ClientConnection) -> None:
            async for _ in socket:
                pass

        drains = [asyncio.create_task(drain(socket)) for socket in sockets[1:]]
        for _ in range(3):  # every panel is open and its first reads are done
            await asyncio.wait_for(status(), 120)
        before = counter.count
        for _ in range(PERIODS):
            await asyncio.wait_for(status(), 120)
        counted = counter.count - before
        for task in drains:
            task.cancel()
        return counted / PERIODS
    finally:
        await asyncio.gather(*(socket.close() for socket in sockets), return_exceptions=True)


def _in_own_loop(work: Coroutine[Any, Any, float]) -> float:
    """``asyncio.run`` on a thread of its own: a browser test earlier in the session (Playwright's sync API) leaves
    an event loop running on the main thread, where asyncio.run refuses to start another."""
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(asyncio.run, work).result()


def test_a_hundred_viewers_in_two_languages_cost_the_bus_what_one_viewer_costs(served: tuple[str, str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "control_panels_per_node", 200)  # the first run's viewer may still be leaving
    base, channel = served
    counter = RequestCounter()
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    notifier = can.Notifier(wire, [counter])
    try:
        one = _in_own_loop(_requests_per_period(base, counter, 1))
        hundred = _in_own_loop(_requests_per_period(base, counter, 100))
    finally:
        notifier.stop()
        wire.shutdown()
    assert one > 0
    assert hundred <= one * (PERIODS + 1) / PERIODS, (one, hundred)  # equal within one period's reads


def test_each_viewer_reads_the_shared_status_in_its_language(client: TestClient) -> None:
    with contextlib.ExitStack() as stack:
        states = {}
        for language in ("en", "de"):
            socket = stack.enter_context(client.websocket_connect(
                _socket(f"reader-{language}"), headers={"Accept-Language": language}))
            while (message := socket.receive_json())["type"] != "status":
                pass
            states[language] = message["status"]
        assert states["en"]["state"] == states["de"]["state"]
        assert states["en"]["status_bits"] != states["de"]["status_bits"]  # the same bits, named in each language
        assert not states["en"]["you_hold"] and not states["de"]["you_hold"]


# --- how many panels a node and a user may open -------------------------------------------------------------------
def _socket(panel: str) -> str:
    return f"/ws/sessions/demo-plant/nodes/{NODE}/control?panel={panel}&operator={panel}"


def _refused(client: TestClient, panel: str, user: str) -> tuple[str, int, str]:
    """The error message and close code and reason of a panel socket that is not let in."""
    with pytest.raises(WebSocketDisconnect) as closed, \
            client.websocket_connect(_socket(panel), headers={"X-DriveBench-User": user}) as socket:
        detail = socket.receive_json()["detail"]
        socket.receive_json()
    return detail, closed.value.code, closed.value.reason


def _watch(stack: contextlib.ExitStack, client: TestClient, panel: str, user: str) -> None:
    """Open a panel socket for the rest of the test (its first message came: it was let in)."""
    socket = stack.enter_context(client.websocket_connect(_socket(panel), headers={"X-DriveBench-User": user}))
    assert socket.receive_json()["type"] in ("status", "error")


def test_a_node_takes_so_many_panels_but_always_its_holders(client: TestClient,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "control_panels_per_node", 2)
    with contextlib.ExitStack() as stack:
        for n in range(2):
            _watch(stack, client, f"watcher{n}", f"user{n}")
        detail, code, reason = _refused(client, "watcher2", "user2")
        assert code == 4429 and detail.startswith("Node 5 already has 2 control panels open, the most it takes")
        assert reason and detail.startswith(reason)
        # the engineer writing the node (its lease) gets in all the same
        written = client.put(f"/api/sessions/demo-plant/nodes/{NODE}/parameters/C00088", json={"value": 12.5},
                             headers={"X-Drive-Panel": "engineer", "X-DriveBench-User": "anna"})
        assert written.status_code == 200, written.text
        _watch(stack, client, "engineer", "anna")


def test_a_user_may_open_so_many_panels_and_gets_one_back_when_one_closes(client: TestClient,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "control_panels_per_user", 2)
    with contextlib.ExitStack() as stack:
        _watch(stack, client, "tab0", "ben")
        with contextlib.ExitStack() as first:
            _watch(first, client, "tab1", "ben")
            detail, code, _reason = _refused(client, "tab2", "ben")
            assert code == 4429 and detail.startswith("ben already has 2 control panels open in this session")
            _watch(stack, client, "tab3", "carla")  # another user is let in

        def admitted() -> bool:  # the closed socket's place is free once the server has seen it close
            try:
                _watch(stack, client, "tab2", "ben")
            except WebSocketDisconnect:
                return False
            return True
        assert wait_until(admitted)
