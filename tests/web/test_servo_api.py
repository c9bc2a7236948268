"""The demo plant's generic CiA 402 servo (node 7) in interpolated position mode (7), over the HTTP API: the mode
is offered because 0x6502 lists it (bit 6), an RPDO is mapped to the control word and the interpolation data
record 0x60C1.1 on the PDO API, and the Control API streams it with SYNC every interpolation period (0x60C2) while
the simulated servo follows the record and answers with status bit 12 *ip mode active*."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import wait_until

AXIS = 7
SESSION = "/api/sessions/demo-plant"
NODE = f"{SESSION}/nodes/{AXIS}"
CONTROL = f"{NODE}/control"


def _read(client: TestClient, ref: str) -> Any:
    response = client.get(f"{NODE}/parameters/{ref}")
    assert response.status_code == 200, response.text
    return response.json()["value"]


def _kept(client: TestClient, condition: Any) -> bool:
    """``condition`` polled while this client keeps the started and armed node alive."""
    def check() -> bool:
        client.post(f"{SESSION}/keepalive")
        return bool(condition())
    return wait_until(check, 15)


@pytest.mark.usefixtures("patient_guard")  # a flow, not the 2 s deadline: a loaded clean-clone run quick-stopped the
# drive between its enable and the cyclic setpoint (four requests in between)
def test_interpolated_position_through_sync_and_an_rpdo(client: TestClient) -> None:
    assert _kept(client, lambda: client.get(CONTROL).json()["state"] == "switch_on_disabled")
    status = client.get(CONTROL).json()
    assert status["modes"]["7"] == "Interpolated position"
    mapped = client.put(f"{NODE}/pdos/rpdo/2", json={"entries": [[0x6040, 0], [0x60C1, 1]],
                                                      "transmission_type": 1})
    assert mapped.status_code == 200 and mapped.json()["ok"], mapped.text
    started = confirmed(client, "POST", f"{NODE}/nmt", json={"command": "start", "confirm": AXIS,
                                                                "keepalive_s": 10})
    assert started.status_code == 200, started.text
    assert _kept(client, lambda: client.get(NODE).json()["nmt_state"] == "Operational")  # its heartbeat says so
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{CONTROL}/commands/{command}").status_code == 200
    assert confirmed(client, "POST", f"{CONTROL}/commands/enable_operation", json={"confirm": AXIS}).status_code == 200
    assert confirmed(client, "PUT", f"{CONTROL}/mode", json={"mode": 7, "confirm": AXIS}).json()["mode_label"] == \
        "Interpolated position"

    unconfirmed = client.post(f"{CONTROL}/cyclic", json={"value": 90})
    assert unconfirmed.status_code == 428, unconfirmed.text
    beyond = confirmed(client, "POST", f"{CONTROL}/cyclic", json={"value": 5000, "confirm": AXIS})
    assert beyond.status_code == 422 and "3600" in beyond.json()["detail"]  # software position limits 0x607D
    sent = confirmed(client, "POST", f"{CONTROL}/cyclic", json={"value": 90, "confirm": AXIS})
    assert sent.status_code == 200, sent.text
    stream = sent.json()
    assert (stream["mode"], stream["rpdo"], stream["cob_id"], stream["period_ms"]) == (7, 2, 0x307, 10)
    assert stream["data"] == "1F 00 5A 00 00 00"  # bit 4 enable ip mode; 0x60C1.1 = 90 °
    assert _kept(client, lambda: _read(client, "0x6064") == 90)
    status = client.get(CONTROL).json()
    assert status["status_bits"][12]["set"] and status["status_bits"][10]["set"]  # ip mode active, at the record
    assert client.delete(f"{CONTROL}/cyclic").json() == {"stopped": 1}
    assert client.post(f"{CONTROL}/commands/quick_stop").status_code == 200
    assert _kept(client, lambda: client.get(CONTROL).json()["state"] == "switch_on_disabled")
