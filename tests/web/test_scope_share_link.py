"""Issue 31 item 4: a read-only share link (the Remote tab's remote-diagnostics links) that shows the scope watches a
running recording and opens and exports stored ones, through the real app, websocket and gate on the demo plant;
starting, stopping and deleting stay refused in words, and a link that does not show the scope reads none of it."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

API = "/api/sessions/demo-plant"
MOTEC = 5  # the 8400 motec has no free TPDO: the recording polls it, nothing needs a confirmation
BODY: dict[str, Any] = {"channels": [{"node": MOTEC, "ref": "C00868/2"}], "period_ms": 50, "length_s": 100.0,
                        "trigger": {"mode": "free"}, "name": "watched"}


def _link(client: TestClient, shows: list[str]) -> TestClient:
    token = client.post("/api/share-links", json={"ttl_minutes": 5, "shows": shows}).json()["token"]
    holder = TestClient(client.app)  # the link holder: its own cookies, only the link
    holder.headers["Authorization"] = f"Bearer {token}"
    return holder


def test_a_link_that_shows_the_scope_watches_opens_and_exports_but_never_starts_stops_or_deletes(
        demo_api: TestClient) -> None:
    holder = _link(demo_api, ["health", "scope"])
    started = demo_api.post(f"{API}/scope/run", json=BODY)
    assert started.status_code == 201, started.text

    with holder.websocket_connect("/ws/sessions/demo-plant/scope") as socket:
        rows: list[list[Any]] = []
        while sum(row[2] is not None for row in rows) < 3:
            message = socket.receive_json()
            if message["type"] == "rows":
                rows += message["rows"]
    state = holder.get(f"{API}/scope/run")
    assert state.status_code == 200 and state.json()["state"] == "recording"

    for method, url in (("POST", f"{API}/scope/run"), ("POST", f"{API}/scope/run/stop")):
        refused = holder.request(method, url, json=BODY)
        assert refused.status_code == 403 and refused.headers["content-type"] == "application/problem+json"
        assert "cannot start, stop or delete a recording" in refused.json()["detail"], refused.json()
    assert demo_api.get(f"{API}/scope/run").json()["state"] == "recording", "the link stopped nothing"

    stopped = demo_api.post(f"{API}/scope/run/stop").json()
    recording_id = stopped["recording_id"]
    assert [r["id"] for r in holder.get("/api/scope/recordings").json()] == [recording_id]
    opened = holder.get(f"/api/scope/recordings/{recording_id}").json()
    assert opened["name"] == "watched" and opened["count"] >= 3
    exported = holder.get(f"/api/scope/recordings/{recording_id}/export?format=csv")
    assert exported.status_code == 200 and exported.text.startswith("sample,time_s")
    assert holder.get(f"/api/scope/recordings/{recording_id}/export?format=json").json()["values"] == opened["values"]

    deleted = holder.delete(f"/api/scope/recordings/{recording_id}")
    assert deleted.status_code == 403 and "cannot start, stop or delete" in deleted.json()["detail"]
    assert demo_api.get(f"/api/scope/recordings/{recording_id}").status_code == 200, "still stored"

    page = holder.get("/scope/demo-plant", follow_redirects=False)
    assert page.status_code == 200 and 'data-read-only="1"' in page.text
    assert 'id="scope-start"' not in page.text and 'id="channel-node"' not in page.text
    remote = holder.get(holder.get("/remote", follow_redirects=False).headers["location"])
    assert "../scope/demo-plant" in remote.text, "the remote view leads to the Scope page"


def test_a_link_that_does_not_show_the_scope_reads_none_of_it(demo_api: TestClient) -> None:
    holder = _link(demo_api, ["health", "bus"])
    assert holder.get("/api/scope/recordings").status_code == 403
    assert holder.get(f"{API}/scope/run").status_code == 403
    assert holder.get("/scope/demo-plant", follow_redirects=False).status_code == 303, "led to the remote view"
    with pytest.raises(WebSocketDisconnect) as closed, holder.websocket_connect("/ws/sessions/demo-plant/scope") as s:
        s.receive_json()
    assert closed.value.code == 4403
