"""What a scope recording may change and must put back: a node's SYNC (0x1005, 0x1006) and TPDO (0x18xx, 0x1Axx)
settings, read through the parameters API in one batch."""

from __future__ import annotations

from fastapi.testclient import TestClient


def tpdo_and_sync_settings(client: TestClient, node_api: str) -> dict[str, object]:
    """``node_api``: the node's API path (``/api/sessions/demo-plant/nodes/7``). Ref -> raw value (or the refusal)."""
    listed = client.get(f"{node_api}/parameters").json()["parameters"]
    refs = [p["ref"] for p in listed if int(p["index"], 16) in (0x1005, 0x1006)
            or 0x1800 <= int(p["index"], 16) <= 0x19FF or 0x1A00 <= int(p["index"], 16) <= 0x1BFF]
    answer = client.post(f"{node_api}/parameters:read", json={"refs": refs})
    assert answer.status_code == 200 and refs, answer.text
    return {item["ref"]: item["value"]["raw"] if item["ok"] else item["error"]["detail"]
            for item in answer.json()["items"]}
