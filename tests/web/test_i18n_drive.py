"""The German UI of drive control, diagnostics and PDOs over the real HTTP API on the demo plant: the standard CiA 402
names of the generic servo (node 7) in German, a vendor section's own texts as its manual prints them, refusals in
words of the reader's language, and a stop recorded by the keep-alive guard put into each reader's words."""

from __future__ import annotations

import json
import time
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.confirming import confirmed
from tests.conftest import wait_until

API = "/api/sessions/demo-plant/nodes"
UI = "/ui/sessions/demo-plant/nodes"
GERMAN = {"Accept-Language": "de-DE,de;q=0.9,en;q=0.5"}
SERVO, MM = 7, 3


def _status(client: TestClient, node: int, headers: dict[str, str] | None = None) -> dict[str, Any]:
    answer = client.get(f"{API}/{node}/control", headers=headers or {})
    assert answer.status_code == 200, answer.text
    return dict(answer.json())


def _until(client: TestClient, node: int, state: str) -> None:
    assert wait_until(lambda: _status(client, node)["state"] == state, 8.0), f"node {node} never in {state}"


@pytest.mark.only_reads
def test_the_control_tab_of_the_generic_servo_shows_cia402_in_german(client: TestClient) -> None:
    _until(client, SERVO, "switch_on_disabled")
    german = client.get(f"{UI}/{SERVO}/control", headers=GERMAN)
    assert german.status_code == 200
    page = german.text
    for text in (">Stillsetzen<", ">Einschalten<", ">Betrieb freigeben<", ">Schnellhalt<",  # transition buttons
                 ">Einschaltsperre<", ">Betrieb freigegeben<", ">Störung<",  # the drawn states
                 ">2 Stillsetzen<", ">15 Fehler quittieren<",  # the arrows
                 "Schnellhalt (0 = aktiv)", "Ziel erreicht",  # control and status word bits
                 "6 Referenzfahrt", "Cyclic Synchronous Position",  # modes of operation (CiA's names, as the catalogue)
                 "CiA-402-Zustandsmaschine des Antriebs"):
        assert text in page, text
    for english in (">Shutdown<", ">Enable operation<", ">Switch on disabled<", ">Target reached<"):
        assert english not in page, english
    plain = client.get(f"{UI}/{SERVO}/control").text
    assert ">Shutdown<" in plain and ">Switch on disabled<" in plain and ">2 Shutdown<" in plain


@pytest.mark.only_reads
def test_the_status_api_names_standard_texts_in_german_and_a_vendors_as_printed(client: TestClient) -> None:
    _until(client, SERVO, "switch_on_disabled")
    servo = _status(client, SERVO, GERMAN)
    assert servo["state_label"] == "Einschaltsperre" and servo["title"] == "CiA-402-Zustandsmaschine des Antriebs"
    assert servo["commands"]["enable_operation"] == "Betrieb freigeben"
    assert servo["commands"]["shutdown"] == "Stillsetzen"
    assert servo["status_bits"][10]["name"] == "Ziel erreicht"
    assert servo["status_bits"][9]["name"] == "Remote (Steuerwort wird verarbeitet)"  # not the Remote page's word
    assert servo["control_bits"][7]["name"] == "Fehler quittieren"
    assert servo["modes"]["6"] == "Referenzfahrt" and servo["modes"]["1"] == "Profile Position"
    assert [bit["name"] for bit in servo["inputs"]][:3] == ["Negativer Endschalter", "Positiver Endschalter",
                                                            "Referenzschalter"]
    english = _status(client, SERVO)
    assert english["state_label"] == "Switch on disabled" and english["commands"]["shutdown"] == "Shutdown"
    assert english["modes"]["6"] == "Homing" and english["error_text"] == "No error"
    # MICROMASTER: the section's own texts stay as the Siemens manual prints them; its standard CiA 402 names in German
    micromaster = _status(client, MM, GERMAN)
    names = [bit["name"] for bit in micromaster["status_bits"]]
    assert names[0] == "Einschaltbereit" and names[4] == "Voltage enabled (MM: OFF2)"
    assert micromaster["control_bits"][7]["name"] == "Fault reset (fault acknowledge)"
    jog = client.get(f"{API}/{MM}/control/jog", headers=GERMAN).json()["text"]  # DriveBench's words, the manual's why
    assert jog.startswith("Sollwert-Tippen mit 10 Prozent des Bereichs") and "the MICROMASTER CANopen manual" in jog


@pytest.mark.only_reads
def test_homing_methods_are_named_in_each_readers_language(client: TestClient) -> None:
    german = client.get(f"{API}/{SERVO}/control/motion", headers=GERMAN).json()
    assert german["homing_methods"]["34"] == "Nullimpuls in positiver Richtung"
    assert german["homing_methods"]["7"].startswith("Referenzschalter und Nullimpuls: Start in Richtung positiv")
    assert any(setting["label"] == "Maximale Profilgeschwindigkeit" for setting in german["settings"])
    english = client.get(f"{API}/{SERVO}/control/motion").json()  # the methods read once are not kept in German
    assert english["homing_methods"]["34"] == "Index pulse in positive direction"
    assert english["homing_methods"]["7"] == ("Home switch and index pulse: start positive, reverse at the positive "
                                              "limit switch, index below the switch's lower edge")


def test_a_refused_move_and_an_unconfirmed_enable_answer_in_german(client: TestClient) -> None:
    _until(client, SERVO, "switch_on_disabled")
    move = confirmed(client, "POST", f"{API}/{SERVO}/control/move", json={"target": 10, "confirm": SERVO},
                     headers=GERMAN)
    assert move.status_code == 409, move.text
    assert move.json()["detail"] == ("Eine Profilpositionsfahrt braucht den Antrieb im Zustand Betrieb freigegeben "
                                     "(er ist in 'Einschaltsperre').")
    plain = confirmed(client, "POST", f"{API}/{SERVO}/control/move", json={"target": 10, "confirm": SERVO})
    assert plain.json()["detail"] == ("A profile-position move needs the drive in operation enabled (it is in "
                                      "'Switch on disabled').")
    homing = confirmed(client, "POST", f"{API}/{SERVO}/control/home", json={"method": 99, "confirm": SERVO},
                       headers=GERMAN)
    assert homing.status_code == 422 and homing.json()["detail"].startswith("Die Referenzfahrt-Methode 99 (reserviert")
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{API}/{SERVO}/control/commands/{command}").status_code == 200
    unconfirmed = client.post(f"{API}/{SERVO}/control/commands/enable_operation", headers=GERMAN)
    assert unconfirmed.status_code == 428
    assert unconfirmed.json()["detail"].startswith("Betrieb freigeben ") and "Knoten 7" in unconfirmed.json()["detail"]
    assert client.post(f"{API}/{SERVO}/control/commands/shutdown").status_code == 200


def test_a_stop_by_the_keep_alive_guard_reads_in_each_readers_language(client: TestClient) -> None:
    _until(client, SERVO, "switch_on_disabled")
    for command in ("shutdown", "switch_on"):
        assert client.post(f"{API}/{SERVO}/control/commands/{command}").status_code == 200
    enabled = confirmed(client, "POST", f"{API}/{SERVO}/control/commands/enable_operation", json={"confirm": SERVO},
                        headers=GERMAN)
    assert enabled.status_code == 200 and enabled.json()["armed"]
    assert " an testclient seit " in enabled.json()["holder"]  # who holds it, in the German reader's words
    # no keep-alive: the guard stops the drive on its own (a background task) and keeps what it did
    assert wait_until(lambda: _status(client, SERVO)["last_trip"] is not None, 8.0)
    english, german = _status(client, SERVO)["last_trip"], _status(client, SERVO, GERMAN)["last_trip"]
    assert english.startswith("Quick stop sent at ") and "no keep-alive for 2 s (held by " in english
    assert german.startswith("Schnellhalt gesendet um ") and "kein Keep-Alive seit 2 s (gehalten von " in german
    assert english.split(" ")[4] == german.split(" ")[3]  # the same clock time


def test_pdo_and_diagnostics_refusals_answer_in_german(client: TestClient) -> None:
    too_long = {"entries": [[0x6040, 0], [0x6042, 0], [0x2802, 3], [0x2802, 4], [0x6071, 0]]}
    answer = client.put(f"{API}/{MM}/pdos/rpdo/5", json=too_long, headers=GERMAN)
    assert answer.status_code == 422
    assert answer.json()["detail"] == "RPDO5 nimmt höchstens 4 Mapping-Einträge; angegeben waren 5."
    fixed = client.put(f"{API}/{MM}/pdos/rpdo/1", json={"entries": [[0x6040, 0]]}, headers=GERMAN)
    assert fixed.json()["detail"].startswith("Das Mapping von RPDO1 ist bei diesem Gerät fest")
    german = {pdo["transmission_text"] for pdo in client.get(f"{API}/{MM}/pdos", headers=GERMAN).json()}
    english = {pdo["transmission_text"] for pdo in client.get(f"{API}/{MM}/pdos").json()}
    assert "synchron, azyklisch" in german and "synchronous, acyclic" in english
    own = client.put(f"{API}/{SERVO}/heartbeat/consumers/1", json={"producer_id": SERVO, "time_ms": 500},
                     headers=GERMAN)
    assert own.status_code == 422 and own.json()["detail"] == "Knoten 7 kann seinen eigenen Heartbeat nicht überwachen."


def _flood_of(socket: Any, timeout_s: float = 20.0) -> dict[str, Any]:
    """The flood a monitor websocket reports first (its messages come every 0.25 s)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = json.loads(socket.receive_text())
        flood = message.get("snapshot", {}).get("flood")
        if flood:
            return dict(flood)
    raise AssertionError("the monitor never named the flood")


def test_the_monitor_names_a_babbling_node_in_each_viewers_language(client: TestClient) -> None:
    plant = client.app.state.drivebench.plants["demo-plant"]  # type: ignore[attr-defined]
    plant.start_babbler(0x001)
    try:
        url = "/ws/sessions/demo-plant/monitor?rows=1"
        with client.websocket_connect(url, headers=GERMAN) as german, client.websocket_connect(url) as english:
            assert _flood_of(german)["text"].startswith("COB-ID 0x001 überflutet den Bus: ")
            assert _flood_of(english)["text"].startswith("COB-ID 0x001 floods the bus: ")  # one feed, two languages

        def rest_says_it() -> bool:
            flood = client.get("/api/sessions/demo-plant/monitor?trace=0", headers=GERMAN).json()["flood"]
            return bool(flood) and flood["text"].startswith("COB-ID 0x001 überflutet den Bus: ")
        assert wait_until(rest_says_it, 20.0)
    finally:
        plant.stop_babbler()


@pytest.mark.only_reads
def test_the_pdo_and_diagnostics_tabs_leave_no_english_half_sentence(client: TestClient) -> None:
    pdo_tab = client.get(f"{UI}/{MM}/pdo", headers=GERMAN)
    assert pdo_tab.status_code == 200
    assert "bis Objekte gemappt sind (RPDO5 bearbeiten)" in pdo_tab.text
    assert "until objects are mapped" not in pdo_tab.text
    assert "PDO-mappbare Objekte (schreibbar, für ein RPDO)" in pdo_tab.text and "0 ms (aus)" in pdo_tab.text
    assert "until objects are mapped (Edit RPDO5)" in client.get(f"{UI}/{MM}/pdo").text
    diagnostics = client.get(f"{UI}/{SERVO}/diagnostics", headers=GERMAN).text  # node 7 has no 0x1016
    assert "<strong>SDO-Übertragung abgebrochen</strong>" in diagnostics and "SDO transfer aborted" not in diagnostics
