"""What a share link shows beyond node health (issue 30 item 6), through the real app on the demo plant: the link
stores what it shows, the MICROMASTER's tripped fault arrives in the manual's words with its history, the values
last read on site carry their age, the bus's load and counters are there when chosen, and the link holder's reads
cause no SDO frame on the wire."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, wait_for_value

NODE = 3
F0070 = 0x7001  # EMCY code of MICROMASTER fault F0070 (CANopen option module manual, Table 3-14)
EVERYTHING = ["health", "faults", "emcy", "parameters", "bus"]


class SdoRequests(can.Listener):
    """SDO requests to any node seen on the wire (a python-can bus of its own on the plant's channel)."""

    def __init__(self) -> None:
        self.count = 0
        self.lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        if 0x601 <= msg.arbitration_id <= 0x67F:
            with self.lock:
                self.count += 1


@pytest.fixture
def demo() -> Iterator[tuple[TestClient, Plant, str]]:
    channel = fresh_channel()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as client:
        plants: dict[str, Plant] = app.state.drivebench.plants
        yield client, next(iter(plants.values())), channel


def _node(content: list[dict[str, Any]], node_id: int) -> dict[str, Any]:
    node: dict[str, Any] = next(n for n in content[0]["nodes"] if n["node_id"] == node_id)
    return node


def test_a_link_stores_what_it_shows_and_refuses_unknown_parts(demo: tuple[TestClient, Plant, str]) -> None:
    client, _, _ = demo
    default = client.post("/api/share-links", json={"ttl_minutes": 5}).json()
    assert default["shows"] == ["health", "faults"]
    chosen = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": ["bus", "faults"]}).json()
    assert chosen["shows"] == ["faults", "bus"]
    listed = {link["id"]: link["shows"] for link in client.get("/api/share-links").json()}
    assert listed[chosen["id"]] == ["faults", "bus"] and listed[default["id"]] == ["health", "faults"]

    refused = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": ["health", "scope"]})
    assert refused.status_code == 422 and "cannot show scope" in refused.json()["detail"]
    nothing = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": []})
    assert nothing.status_code == 422 and "at least one" in nothing.json()["detail"]

    content = client.get(f"/api/remote/{default['token']}/content").json()
    mm4 = _node(content, NODE)
    assert mm4["history"] == [] and mm4["present"] is None
    assert mm4["last_emcys"] is None and mm4["values"] is None and content[0]["bus"] is None, "not chosen"
    assert client.get("/api/remote/dbv_wrong/content").status_code == 401


def test_link_shows_the_trip_in_words_the_values_read_and_the_bus_without_an_sdo_frame(
        demo: tuple[TestClient, Plant, str]) -> None:
    client, plant, channel = demo
    read = client.post(f"/api/sessions/demo-plant/nodes/{NODE}/parameters:read", json={"refs": ["r0947"]}).json()
    assert read["items"][0]["ok"], read  # read on site: the link shows it with its age
    token = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": EVERYTHING}).json()["token"]
    viewer = TestClient(client.app)  # the link holder: its own cookies, only the link
    wire = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    requests = SdoRequests()
    notifier = can.Notifier(wire, [requests])
    try:
        plant.nodes[NODE].drive.raise_fault(70, F0070)

        def tripped() -> dict[str, Any] | None:
            node = _node(viewer.get(f"/api/remote/{token}/content").json(), NODE)
            return node if node["present"] else None
        mm4 = wait_for_value(tripped, 15.0, "the trip in the link's content")
        time.sleep(0.5)  # any frame the link's reads caused is on the wire by now
        page = viewer.get(f"/remote/{token}")
    finally:
        notifier.stop()
        wire.shutdown()
    assert requests.count == 0, "the link holder caused SDO traffic"

    fault = mm4["present"]["fault"]
    assert fault["label"] == "F0070" and "Control board setpoint timeout" in fault["text"]
    assert "Check whether the CANopen master has stopped" in fault["remedy"]
    assert mm4["history"] and mm4["history"][0]["fault"]["label"] == "F0070" and mm4["history"][0]["time"] > 0
    assert mm4["last_emcys"][0]["code"] == "0x7001"
    values = {v["ref"]: v for v in mm4["values"]}
    assert "r0947" in values and values["r0947"]["age_s"] >= 0
    assert "r2110" in mm4["not_read"], "never read on site: listed, not read for the link"
    bus = viewer.get(f"/api/remote/{token}/content").json()[0]["bus"]
    assert bus["totals"]["frames"] > 0 and "percent" in bus["load"]

    assert page.status_code == 200
    assert "Control board setpoint timeout" in page.text and "Remedy:" in page.text
    assert "Fault history" in page.text and "Bus load" in page.text and "r0947" in page.text
