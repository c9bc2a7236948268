"""8400 motec PDOs in their Lenze setting against the demo plant (node 5): the mapping objects hold count 0 and no
entries (manual I-1600...I-1A01, default 0), yet each PDO carries its port's 4 process data words (ch. 8.1) - the
tab names them, the simulated drive exchanges them, and writing count 0 brings the static mapping back."""

from __future__ import annotations

import time
from typing import Any

from fastapi.testclient import TestClient

from drivebench.simulator.plant import Plant
from tests.confirming import confirmed
from tests.conftest import wait_until

NO_BROWSER = {"keepalive": False, "reason": "test without a browser"}  # NMT start without the keep-alive guard (admin)
SEND = {"confirm": "5", "keepalive": "false", "reason": "test without a browser"}  # RPDO form fields, as above

API = "/api/sessions/demo-plant/nodes/5"
UI = "/ui/sessions/demo-plant/nodes/5"
STATIC = {("rpdo", 1): ["C00866/1", "C00866/2", "C00866/3", "C00866/4"],
          ("rpdo", 2): ["C00866/5", "C00866/6", "C00866/7", "C00866/8"],
          ("tpdo", 1): ["C00868/1", "C00868/2", "C00868/3", "C00868/4"],
          ("tpdo", 2): ["C00868/5", "C00868/6", "C00868/7", "C00868/8"]}


def _plant(client: TestClient) -> Plant:
    plant: Plant = client.app.state.drivebench.plants["demo-plant"]  # type: ignore[attr-defined]
    return plant


def test_count_0_is_shown_as_the_static_port_mapping(client: TestClient) -> None:
    store = _plant(client).nodes[5].store
    assert [store.get(index, 0) for index in (0x1600, 0x1601, 0x1A00, 0x1A01)] == [0, 0, 0, 0], "Lenze setting"
    pdos = client.get(f"{API}/pdos").json()
    assert {(p["direction"], p["number"]): [e["ref"] for e in p["entries"]] for p in pdos} == STATIC
    for config in pdos:
        assert config["static_mapping"] and config["length_bytes"] == 8 and not config["fixed_mapping"]
        assert config["notes"][0].startswith("Static mapping (Lenze setting)")
    rpdo1 = pdos[0]
    assert "wCtrl" in rpdo1["notes"][0] and "CAN1_IN" in rpdo1["notes"][0]
    assert [e["bits"] for e in rpdo1["entries"]] == [16, 16, 16, 16]
    page = client.get(f"{UI}/pdo")
    assert page.status_code == 200
    assert "Nothing mapped" not in page.text and page.text.count("static mapping</span>") == 4
    assert "monitoring time set in C00357/1 for the reception of the PDO CAN1_IN is exceeded" in page.text


def test_the_drive_exchanges_the_port_words(client: TestClient) -> None:
    """RPDO1 word 1 = control word, word 2 = setpoint reach C00866/1, /2; TPDO1 sends the status word C00868/1."""
    sim = _plant(client).nodes[5]
    client.get(f"{UI}/pdo")  # reads the mappings the sender packs by and the live view decodes by
    with client.websocket_connect("/ws/sessions/demo-plant/nodes/5/process-data") as ws:
        hello = ws.receive_json()
        tpdo1 = next(p for p in hello["pdos"] if (p["direction"], p["number"]) == ("tpdo", 1))
        assert [s["ref"] for s in tpdo1["signals"]] == STATIC[("tpdo", 1)]
        # event-driven TPDOs go out once on the start
        confirmed(client, "POST", f"{API}/nmt", json={"command": "start", "confirm": 5, **NO_BROWSER})
        assert wait_until(lambda: sim.state.name == "OPERATIONAL")
        sent = confirmed(client, "POST", f"{UI}/pdo/rpdo/1/send", data={**SEND, "mode": "once", "v:C00866/2": "4660"})
        assert sent.status_code == 200 and "00 00 34 12 00 00 00 00" in sent.text, sent.text
        assert wait_until(lambda: sim.store.get_ref("C00866/2") == 0x1234)
        deadline = time.monotonic() + 10
        sample: dict[str, Any] | None = None
        while time.monotonic() < deadline and sample is None:
            for candidate in ws.receive_json().get("samples", []):
                if candidate["cob_id"] == 0x185:
                    sample = candidate
        assert sample is not None, "no TPDO1 from the 8400 motec"
        assert len(bytes.fromhex(sample["data"].replace(" ", ""))) == 8
        status = next(s for s in sample["signals"] if s["ref"] == "C00868/1")
        assert status["bit_offset"] == 0


def test_writing_count_0_restores_the_static_mapping(client: TestClient) -> None:
    explicit = client.put(f"{API}/pdos/tpdo/2", json={"entries": [[0x5C9B, 5]]})
    assert explicit.status_code == 200 and explicit.json()["ok"], explicit.text
    assert [e["ref"] for e in explicit.json()["pdo"]["entries"]] == ["C00868/5"]
    assert not explicit.json()["pdo"]["static_mapping"]
    back = client.put(f"{API}/pdos/tpdo/2", json={"entries": []})
    assert back.status_code == 200 and back.json()["ok"], back.text
    assert back.json()["pdo"]["static_mapping"] and "static mapping" in back.json()["message"]
    assert [e["ref"] for e in back.json()["pdo"]["entries"]] == STATIC[("tpdo", 2)]
