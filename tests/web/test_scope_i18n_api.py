"""The oscilloscope's texts in each reader's language, through the real HTTP API and the scope websocket on the demo
plant (the CiA 402 servo, node 7, sampled by PDO at 10 ms): a recording started and stopped by an English client
tells a German reader what it restored in German (over GET .../scope/run and over the scope socket) and the English
one still in English; a source's marker (the adapter went bus-off) reaches a German socket in German, and a German
reader of the stored recording sees it in German too. The texts are made once, by whichever request or task ended
the recording; each reader gets them in their own language."""

from __future__ import annotations

from typing import Any

import can
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketTestSession

from drivebench.services.bus.sessions import Session
from drivebench.services.scope import runs
from drivebench.transport.bus import SimulatedAdapter
from tests.confirming import confirmed
from tests.conftest import wait_until

AXIS = 7
API = "/api/sessions/demo-plant"
SOCKET = "/ws/sessions/demo-plant/scope"
GERMAN = {"Accept-Language": "de-DE,de;q=0.9"}
ENGLISH = {"Accept-Language": "en"}
BODY: dict[str, Any] = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x6041"}],
                        "period_ms": 10, "length_s": 100.0, "trigger": {"mode": "free"}, "name": "languages"}
BUS_OFF_DE = "Der CAN-Adapter ist Bus-Off: es werden keine Telegramme gesendet oder empfangen."
BUS_OFF_EN = "The CAN adapter is bus-off: no frames are sent or received."


def _session(client: TestClient) -> Session:
    return client.app.state.drivebench.manager.get("demo-plant")  # type: ignore[attr-defined,no-any-return]


def _start_in_english(client: TestClient) -> runs.ScopeRun:
    started = confirmed(client, "POST", f"{API}/scope/run", json=BODY, headers=ENGLISH)
    assert started.status_code == 201 and started.json()["source"] == "pdo", started.text
    run = runs.current(_session(client))
    assert wait_until(lambda: sum(row[2] is not None for row in list(run.live)) >= 5, 30), list(run.live)[-5:]
    return run


def _until(socket: WebSocketTestSession, wanted: Any, most: int = 2000) -> dict[str, Any]:
    """The socket's first message ``wanted`` accepts (at most ``most`` messages read)."""
    for _n in range(most):
        message: dict[str, Any] = socket.receive_json()
        if wanted(message):
            return message
    raise AssertionError("the socket never sent the message")


def _marker_texts_until_bus_off(socket: WebSocketTestSession) -> list[str]:
    """Every marker's text the socket sends up to the bus-off one, in either language (a loaded machine adds
    "SYNC paused" markers before it)."""
    texts: list[str] = []
    while BUS_OFF_DE not in texts and BUS_OFF_EN not in texts:
        texts += [event["text"] for event in _until(socket, lambda m: m["type"] == "events")["events"]]
    return texts


def _assert_german(restored: list[str]) -> None:
    assert restored[0].startswith("SYNC: ") and "gesendet mit einer mittleren Periode von" in restored[0], restored
    assert any(text.startswith(f"Knoten {AXIS}: TPDO") and "wiederhergestellt und wie vorher zurückgelesen" in text
               for text in restored), restored
    assert not any("sent at a mean period" in text or "read back as before" in text for text in restored), restored


def _assert_english(restored: list[str]) -> None:
    assert restored[0].startswith("SYNC: ") and "sent at a mean period of" in restored[0], restored
    assert any(text.startswith(f"Node {AXIS}: TPDO") and "restored and read back as before" in text
               for text in restored), restored
    assert not any("Knoten" in text or "gesendet" in text for text in restored), restored


def test_the_restore_list_of_an_english_stop_is_german_for_a_german_reader(demo_api: TestClient) -> None:
    _start_in_english(demo_api)
    with demo_api.websocket_connect(SOCKET, headers=GERMAN) as german_page:
        _until(german_page, lambda m: m["type"] == "state" and m["state"] == "recording")
        stopped = demo_api.post(f"{API}/scope/run/stop", headers=ENGLISH).json()
        assert stopped["state"] == "stopped", stopped
        _assert_english(stopped["restored"])
        shown = _until(german_page, lambda m: m["type"] == "state" and m["state"] == "stopped")
    _assert_german(shown["restored"])
    assert shown["source_name"] == "Abtastung per PDO", shown["source_name"]
    german = demo_api.get(f"{API}/scope/run", headers=GERMAN).json()
    english = demo_api.get(f"{API}/scope/run", headers=ENGLISH).json()
    _assert_german(german["restored"])
    _assert_english(english["restored"])
    assert len(german["restored"]) == len(english["restored"]) == len(stopped["restored"])
    with demo_api.websocket_connect(SOCKET, headers=ENGLISH) as english_page:  # a page opened after the stop
        _assert_english(_until(english_page, lambda m: m["type"] == "state")["restored"])


def test_a_source_marker_is_german_live_and_stored_for_a_german_reader(demo_api: TestClient) -> None:
    run = _start_in_english(demo_api)
    adapter: SimulatedAdapter | None = _session(demo_api).network.bus.adapter
    assert adapter is not None, "a virtual bus has a simulated adapter"
    with demo_api.websocket_connect(SOCKET, headers=GERMAN) as german_page:
        _until(german_page, lambda m: m["type"] == "state" and m["state"] == "recording")
        adapter.report(can.BusState.ERROR)  # bus-off: the source's marker, made in the source's own task
        try:
            assert wait_until(lambda: any(e.text == BUS_OFF_EN for e in run.events), 30), run.events
        finally:
            adapter.report(can.BusState.ACTIVE)
        texts = _marker_texts_until_bus_off(german_page)
        assert BUS_OFF_DE in texts and BUS_OFF_EN not in texts, texts
        stopped = demo_api.post(f"{API}/scope/run/stop", headers=ENGLISH).json()
    assert stopped["state"] == "stopped" and stopped["recording_id"], stopped
    recording = f"/api/scope/recordings/{stopped['recording_id']}"
    german = [m["text"] for m in demo_api.get(recording, headers=GERMAN).json()["markers"] if m["kind"] == "source"]
    english = [m["text"] for m in demo_api.get(recording, headers=ENGLISH).json()["markers"]
               if m["kind"] == "source"]
    assert BUS_OFF_DE in german and BUS_OFF_EN not in german, german
    assert BUS_OFF_EN in english and BUS_OFF_DE not in english, english
    exported = demo_api.get(f"{recording}/export?format=json", headers=GERMAN).json()
    assert BUS_OFF_DE in [m["text"] for m in exported["markers"]], exported["markers"]
