"""EtherCAT pages in EtherCAT's words (issue 28 item 9): no NMT, heartbeat or 'Reset node' for a slave of the demo
plant's EtherCAT line, over the real pages and the remote view of a share link."""

from __future__ import annotations

import re

from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import wait_until

SESSION = "ethercat-line"


def _section(page: str, name: str) -> str:
    start = page.index(f"<h2>{name}</h2>")
    return page[start:page.index("</section>", start)]


def test_remote_view_shows_ethercat_states_not_nmt_and_heartbeats(demo_api: TestClient) -> None:
    made = demo_api.post("/api/share-links", json={"ttl_minutes": 5})
    assert made.status_code == 201, made.text
    view = demo_api.get(f"/remote/{made.json()['token']}")
    assert view.status_code == 200
    ecat = _section(view.text, "EtherCAT line")
    assert "EtherCAT state" in ecat and "Slave" in ecat
    for word in ("NMT state", "Heartbeat age", "Boot-ups", "heartbeat lost"):
        assert word not in ecat, word
    can = _section(view.text, "Demo plant")
    assert "NMT state" in can and "Heartbeat age" in can  # CAN keeps them


def test_ethercat_node_page_says_re_initialise_not_reset_node(demo_api: TestClient) -> None:
    page = demo_api.get(f"/sessions/{SESSION}/nodes/1").text
    head = page[page.index('class="node-head"'):page.index("</section>", page.index('class="node-head"'))]
    assert not re.search(r"Reset node", head), "an EtherCAT slave has no NMT 'Reset node'"
    assert "Re-initialise slave" in head
    can = demo_api.get("/sessions/demo-plant/nodes/3").text
    assert ">Reset node</button>" in can


def test_a_dropped_ethercat_slave_is_tripped_in_ethercat_words(demo_api: TestClient) -> None:
    """The page that started slave 1 closes: the trip names the EtherCAT state it asked for, not an NMT command."""
    tab = {"X-DriveBench-Client": "tab-words"}
    node = f"/api/sessions/{SESSION}/nodes/1"
    with demo_api.websocket_connect(f"/ws/sessions/{SESSION}/keepalive?client=tab-words") as socket:
        started = confirmed(demo_api, "POST", f"{node}/nmt", json={"command": "start"}, headers=tab)
        assert started.status_code == 200, started.text
        socket.send_text('{"cmd": "keepalive"}')
        assert socket.receive_json()["nodes"] == [1]
    def trip() -> str:
        return str(demo_api.get(f"{node}/control").json()["last_trip"] or "")

    # the trip is named at once and gets its steps (the state change) when they are done
    assert wait_until(lambda: "Pre-Operational" in trip() or "pre-operational" in trip(), 15), trip()
    assert "EtherCAT state Pre-Operational requested" in trip() and "NMT" not in trip(), trip()
