"""The Node page's header: its NMT badge is a fragment of its own that follows the node's state."""

from __future__ import annotations

from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import wait_for_value

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)

BADGE = "/ui/sessions/demo-plant/nodes/5/nmt"


def _badge_after(client: TestClient, text: str) -> str:
    def said() -> str:
        html = client.get(BADGE).text
        return html if text in html else ""
    shown: str = wait_for_value(said, 10, f"the badge to say {text}")
    return shown


def test_nmt_badge_fragment_changes_after_nmt_start(client: TestClient) -> None:
    page = client.get("/sessions/demo-plant/nodes/5").text
    assert 'id="nmt-badge"' in page and 'hx-get="/ui/sessions/demo-plant/nodes/5/nmt"' in page
    assert ">Pre-operational</span>" in _badge_after(client, "Pre-operational")
    assert confirmed(client, "POST", "/api/sessions/demo-plant/nodes/5/nmt",
                     json={"command": "start", "confirm": 5, **NO_BROWSER}).status_code == 200
    html = _badge_after(client, ">Operational<")
    assert 'class="nmt nmt-operational"' in html and 'hx-trigger="every 1s"' in html


def test_nmt_badge_of_unknown_node_is_not_found(client: TestClient) -> None:
    assert client.get("/ui/sessions/demo-plant/nodes/99/nmt").status_code == 404
