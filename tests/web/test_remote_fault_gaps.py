"""A share link says what the device profile lacks (issue 30 item 4, 'say so, never guess'), through the real app
on the demo plant: node 12 (8200 vector) trips, its Lenze error number has no text in the profile (the 8200 vector's
fault table is not in the sources), and the link holder reads why beside the fault; a fault the profile explains
(MICROMASTER F0070) brings no such note."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant
from tests.conftest import wait_for_value

MM, VECTOR = 3, 12
F0070 = 0x7001  # EMCY code of MICROMASTER fault F0070 (CANopen option module manual, Table 3-14)


def _plant(client: TestClient) -> Plant:
    plants: dict[str, Plant] = client.app.state.drivebench.plants  # type: ignore[attr-defined]
    return plants["demo-plant"]


def _tripped(viewer: TestClient, token: str, node_id: int) -> dict[str, Any]:
    def node() -> dict[str, Any] | None:
        content = viewer.get(f"/api/remote/{token}/content").json()
        found: dict[str, Any] = next(n for n in content[0]["nodes"] if n["node_id"] == node_id)
        return found if found["present"] else None
    return wait_for_value(node, 15.0, f"node {node_id}'s trip in the link's content")


def test_link_says_why_node_12s_fault_number_has_no_text(client: TestClient) -> None:
    token = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": ["faults"]}).json()["token"]
    viewer = TestClient(client.app)  # the link holder: its own cookies, only the link
    calm = next(n for n in viewer.get(f"/api/remote/{token}/content").json()[0]["nodes"] if n["node_id"] == VECTOR)
    assert calm["not_covered"] is None, "no fault shown, nothing to explain"
    _plant(client).nodes[VECTOR].drive.raise_fault(0x10)  # what TRIP-SET raises in the simulated 8200 vector
    vector = _tripped(viewer, token, VECTOR)
    assert vector["present"]["fault"]["label"] == "Lenze error number 16" and vector["present"]["fault"]["text"] is None
    assert "8200 vector system manual" in vector["not_covered"]
    page = viewer.get(f"/remote/{token}")
    assert page.status_code == 200
    assert "Lenze error number 16" in page.text and "this fault number has no text in the device profile" in page.text
    assert "Not covered by the profile's sources:</strong> The 8200 vector&#39;s own fault table" in page.text
    assert "8200 vector system manual" in page.text

    _plant(client).nodes[MM].drive.raise_fault(70, F0070)
    mm4 = _tripped(viewer, token, MM)
    assert mm4["present"]["fault"]["label"] == "F0070" and mm4["not_covered"] is None, "F0070 has its text"
