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
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, wait_for_value

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

    refused = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": ["health", "video"]})
    assert refused.status_code == 422 and "cannot show video" in refused.json()["detail"]
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
        by_viewer = requests.count
        client.post(f"/api/sessions/demo-plant/nodes/{NODE}/parameters:read", json={"refs": ["r2110"]})
        wait_for_value(lambda: requests.count > by_viewer, 10.0, "the engineer's read on the wire (the count works)")
    finally:
        notifier.stop()
        wire.shutdown()
    assert by_viewer == 0, "the link holder caused SDO traffic"

    fault = mm4["present"]["fault"]
    assert fault["label"] == "F0070" and "Control board setpoint timeout" in fault["text"]
    assert "Check whether the CANopen master has stopped" in fault["remedy"]
    assert mm4["history"] and mm4["history"][0]["fault"]["label"] == "F0070" and mm4["history"][0]["time"] > 0
    assert mm4["last_emcys"][0]["code"] == "0x7001"
    values = {v["ref"]: v for v in mm4["values"]}
    assert "r0947" in values and values["r0947"]["age_s"] >= 0
    assert "r2110" in mm4["not_read"], "not read on site then: listed, never read for the link"
    bus = viewer.get(f"/api/remote/{token}/content").json()[0]["bus"]
    assert bus["totals"]["frames"] > 0 and "percent" in bus["load"]

    assert page.status_code == 200
    assert "Control board setpoint timeout" in page.text and "Remedy:" in page.text
    assert "Fault history" in page.text and "Bus load" in page.text and "r0947" in page.text


def test_share_link_in_a_second_browser_shows_the_micromaster_fault_and_history_without_an_sdo_frame(
        demo_server: tuple[str, Plant], browser: Any) -> None:
    base, plant = demo_server
    engineer = browser.new_context(viewport={"width": 1440, "height": 900})
    page = engineer.new_page()
    page.goto(f"{base}/remote")
    page.fill("input[name=label]", "Siemens service, ticket 815")
    assert page.locator("input[name=shows][value=faults]").is_checked(), "default: health + faults"
    assert not page.locator("input[name=shows][value=bus]").is_checked()
    page.check("input[name=shows][value=emcy]")
    page.click("text=Create share link")
    url = page.locator("input.share-url").input_value()
    row = page.locator("#share-links tbody tr", has_text="ticket 815")
    assert "Last emergency telegrams" in row.inner_text() and "Bus load" not in row.inner_text()
    screenshot(page, "remote-content-engineer")

    wire = can.Bus(interface="virtual", channel=plant.spec.channel, receive_own_messages=False)
    requests = SdoRequests()
    notifier = can.Notifier(wire, [requests])
    remote = browser.new_context(viewport={"width": 1440, "height": 900})
    try:
        viewer = remote.new_page()
        viewer.goto(url)
        viewer.wait_for_selector("text=read-only view")
        node = viewer.locator(".remote-node[data-node='3']")
        node.locator(".remote-present-fault").wait_for(timeout=20_000)
        plant.nodes[NODE].drive.raise_fault(70, F0070)  # the simulated drive trips: EMCY 0x7001 + F0070
        viewer.wait_for_selector(".remote-node[data-node='3'] .remote-present-fault >> text=F0070", timeout=20_000)
        present = node.locator(".remote-present-fault").inner_text()
        assert "Control board setpoint timeout" in present
        assert "Remedy: Check whether the CANopen master has stopped" in present
        history = node.locator("table.remote-fault-history tbody tr")
        assert history.count() >= 1 and "F0070" in history.first.inner_text()
        assert "0x7001" in node.locator("table.remote-last-emcys").inner_text()
        assert viewer.locator(".remote-bus").count() == 0, "not chosen for this link"
        assert viewer.locator("button").count() == 0, "the remote view offers no action"
        screenshot(viewer, "remote-content-viewer")
        viewer.wait_for_timeout(1500)  # more pushes of the live view: still no SDO frame
    finally:
        notifier.stop()
        wire.shutdown()
        remote.close()
        engineer.close()
    assert requests.count == 0, "the link holder caused SDO traffic"
