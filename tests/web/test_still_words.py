"""Which writes count as moving (issue 27 items 2, 3 and 4), over the real HTTP API against the simulated demo plant.

A control word passes unasked only if it cannot enable the drive from any state: the fault bits (8400 SetFail,
EMF2178IB TRIP-SET) do not make a word "still", a word carrying the fault-reset bit never is, and a profile cannot
mark the CiA 402 objects still where the standard does not. Device commands (a profile's ``commands`` section) go
through the same check. Stop words (quick stop, disable, controller inhibit) still pass unasked and past another
engineer's lease."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.simulator.node import SimulatedNode
from tests.confirming import confirmed
from tests.conftest import wait_until
from tests.web.test_access import app_client, own_db, users  # noqa: F401  (fixtures)

DEMO, LINE = "demo-plant", "ethercat-line"
MOTEC, SERVO, VECTOR = 5, 7, 12
PROFILES = Path(__file__).parents[2] / "device_profiles"


def _param(session: str, node: int, ref: str) -> str:
    return f"/api/sessions/{session}/nodes/{node}/parameters/{ref}"


def _sim(client: TestClient, node: int) -> SimulatedNode:
    sim: SimulatedNode = client.app.state.drivebench.plants[DEMO].nodes[node]  # type: ignore[attr-defined]
    return sim


def _unit(client: TestClient) -> SimulatedNode:
    slave = client.app.state.drivebench.gateways[LINE].slaves[1001]  # type: ignore[attr-defined]
    node: SimulatedNode = slave.node
    return node


def _refused(client: TestClient, session: str, node: int, ref: str, raw: int,
             headers: dict[str, str] | None = None) -> None:
    answer = client.put(_param(session, node, ref), json={"raw": raw, "verify": False}, headers=headers or {})
    assert answer.status_code == 428, f"{ref} = 0x{raw:04X}: {answer.status_code} {answer.text}"
    assert answer.headers["content-type"] == "application/problem+json"
    assert answer.json()["confirm_node"] == node


def _passed(client: TestClient, session: str, node: int, ref: str, raw: int,
            headers: dict[str, str] | None = None) -> None:
    answer = client.put(_param(session, node, ref), json={"raw": raw, "verify": False}, headers=headers or {})
    assert answer.status_code == 200, f"{ref} = 0x{raw:04X}: {answer.status_code} {answer.text}"


# --- item 2: "still" words that started a drive --------------------------------------------------------------
@pytest.mark.parametrize(("session", "node", "ref", "words"), [
    (DEMO, MOTEC, "C00866/1", (0x4009, 0x4089, 0x4009)),  # SetFail + SwitchOn + EnableOperation, + ResetFault
    (LINE, 1, "C00876/1", (0x4009, 0x4089, 0x4009)),  # the same on the EtherCAT unit
    (DEMO, VECTOR, "C0135", (0x0401, 0x0C01, 0x0401)),  # TRIP-SET + JOG1, + TRIP-RESET
])
def test_fault_words_are_not_still(demo_api: TestClient, session: str, node: int, ref: str,
                                   words: tuple[int, ...]) -> None:
    sim = _unit(demo_api) if session == LINE else _sim(demo_api, node)
    for word in words:
        _refused(demo_api, session, node, ref, word)
    assert not sim.drive.running, "a refused sequence left the drive enabled"  # type: ignore[union-attr]
    state = demo_api.get(f"/api/sessions/{session}/nodes/{node}/control").json()
    assert state["state"] != "operation_enabled" and not state["armed"], state


def test_a_stop_word_with_the_fault_reset_bit_needs_the_confirmation(demo_api: TestClient) -> None:
    _refused(demo_api, DEMO, MOTEC, "C00866/1", 0x0084)  # quick stop + ResetFault: a reset may restart the drive
    _refused(demo_api, DEMO, VECTOR, "C0135", 0x0A00)  # CINH + TRIP-RESET
    _refused(demo_api, DEMO, 3, "0x6040", 0x0080)  # CiA 402: disable voltage + fault reset


def test_stop_words_pass_unasked_and_past_another_engineers_lease(users: dict[str, str],  # noqa: F811
                                                                  app_client: TestClient) -> None:  # noqa: F811
    root = {"Authorization": f"Bearer {users['root']}"}
    eve = {"Authorization": f"Bearer {users['eve']}"}
    for node, ref in ((MOTEC, "C00039/1"), (VECTOR, "C0037")):  # root now holds the node's write lease
        answer = app_client.get(_param(DEMO, node, ref), headers=root)
        assert answer.status_code == 200, answer.text
        held = app_client.put(_param(DEMO, node, ref), json={"raw": answer.json()["raw"], "verify": False},
                              headers=root)
        assert held.status_code == 200, held.text
        assert app_client.put(_param(DEMO, node, ref), json={"raw": answer.json()["raw"]},
                              headers=eve).status_code == 409
    for word in (0x0004, 0x000D, 0x0000, 0x0100, 0x0109):  # quick stop, disable (SwitchOn cleared), inhibit
        _passed(app_client, DEMO, MOTEC, "C00866/1", word, eve)
    for word in (0x0008, 0x0200, 0x0201):  # quick stop, controller inhibit (with a JOG bit)
        _passed(app_client, DEMO, VECTOR, "C0135", word, eve)


# --- item 3: C00002/16 "On / start" enables the controller ----------------------------------------------------
def test_the_8400_enable_controller_command_needs_the_confirmation(demo_api: TestClient) -> None:
    _refused(demo_api, DEMO, MOTEC, "C00002/16", 1)
    answer = confirmed(demo_api, "PUT", _param(DEMO, MOTEC, "C00002/16"), json={"raw": 1, "verify": False})
    assert answer.status_code == 200, answer.text


# --- item 4: a profile cannot switch the check off -----------------------------------------------------------
def _install(client: TestClient, headers: dict[str, str], profile: dict[str, Any]) -> list[dict[str, Any]]:
    """Upload ``profile`` and handle the servo (node 7) with it; the upload's warnings."""
    uploaded = client.post("/api/profiles", headers=headers,
                           files={"file": (f"{profile['id']}.json", json.dumps(profile).encode())})
    assert uploaded.status_code == 201, uploaded.text
    assert client.delete(f"/api/sessions/{DEMO}/nodes/{SERVO}", headers=headers).status_code == 204
    added = client.post(f"/api/sessions/{DEMO}/nodes", json={"node_id": SERVO, "profile_id": profile["id"]},
                        headers=headers)
    assert added.status_code == 201, added.text
    warnings: list[dict[str, Any]] = uploaded.json()["warnings"]
    return warnings


def _servo_profile(new_id: str) -> dict[str, Any]:
    profile: dict[str, Any] = json.loads((PROFILES / "generic-cia402-servo.json").read_text())
    profile["id"] = new_id
    return profile


def test_a_profile_marking_the_control_word_still_for_every_value_does_not_pass_it(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    root = {"Authorization": f"Bearer {users['root']}"}
    profile = _servo_profile("servo-all-still")
    anything = [{"value": "0x0000", "mask": "0x0000", "meaning": "every value"}]
    for obj in profile["objects"]:
        if obj["index"] == "0x6040":
            obj["motion"] = {"kind": "control_word", "still": anything}
        if obj["index"] == "0x60FF":
            obj["motion"] = {"kind": "setpoint", "still": anything}
    warnings = _install(app_client, root, profile)
    assert [w["key"] for w in warnings] == ["0x6040sub0", "0x60FFsub0"], warnings
    assert "the still value 'every value' is ignored" in warnings[0]["message"]
    for word in (0x0006, 0x0007, 0x000F):  # an ignored mark leaves none: stricter than CiA 402, never weaker
        _refused(app_client, DEMO, SERVO, "0x6040", word, root)
    _refused(app_client, DEMO, SERVO, "0x60FF", 5000, root)
    assert _sim(app_client, SERVO).store.get(0x6041, 0) & 0x6F != 0x27, "the servo is not operation enabled"
    assert _sim(app_client, SERVO).store.get(0x60FF, 0) != 5000


def test_a_profile_cannot_weaken_the_standard_still_values(users: dict[str, str],  # noqa: F811
                                                           app_client: TestClient) -> None:  # noqa: F811
    """A sound-looking mark (bit 4 cleared) on 0x6040 counts only where CiA 402 says still too."""
    root = {"Authorization": f"Bearer {users['root']}"}
    profile = _servo_profile("servo-bit4-still")
    for obj in profile["objects"]:
        if obj["index"] == "0x6040":
            obj["motion"] = {"kind": "control_word", "still": [
                {"value": "0x0000", "mask": "0x0010", "meaning": "new set-point (bit 4) cleared"},
                {"value": "0x0000", "mask": "0x0008", "meaning": "enable operation (bit 3) cleared"}]}
    _install(app_client, root, profile)
    _refused(app_client, DEMO, SERVO, "0x6040", 0x000F, root)  # bit 4 clear, but it enables
    _passed(app_client, DEMO, SERVO, "0x6040", 0x0007, root)  # bit 3 clear: still by both


def test_a_profile_command_that_writes_the_control_word_needs_the_confirmation(
        users: dict[str, str], app_client: TestClient) -> None:  # noqa: F811
    root = {"Authorization": f"Bearer {users['root']}"}
    profile = _servo_profile("servo-save-enables")
    profile["commands"] = {"save": {"ref": "0x6040", "value": 15, "done": "Node {node} saved."}}
    _install(app_client, root, profile)
    url = f"/api/sessions/{DEMO}/nodes/{SERVO}/commands/save"
    refused = app_client.post(url, headers=root)
    assert refused.status_code == 428, refused.text
    assert refused.json()["confirm_node"] == SERVO
    assert _sim(app_client, SERVO).store.get(0x6040, 0) != 15, "nothing was written without the confirmation"
    done = confirmed(app_client, "POST", url, headers=root)
    assert done.status_code == 200, done.text
    assert wait_until(lambda: _sim(app_client, SERVO).store.get(0x6040, 0) == 15)
    kept = app_client.post(f"/api/sessions/{DEMO}/keepalive", headers=root).json()
    assert kept["nodes"] == [SERVO], "the confirmed command armed the keep-alive guard"
