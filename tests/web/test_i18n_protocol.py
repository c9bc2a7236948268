"""German problem details of the protocol and transport layers, over the real path (HTTP API or page fragment ->
services -> protocol -> virtual CAN bus -> simulated node): CiA 301 abort texts, stalled and out-of-step transfers,
EMCY classes and adapter errors come back German to a German reader, a device manual's own abort text stays as the
manual prints it, and English readers get the English texts unchanged. An error raised in a bus thread (no request,
no language) keeps its words until a reader asks for them."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench import i18n
from drivebench.errors import DriveBenchError
from drivebench.protocol.canopen.network import CanopenNetwork
from drivebench.simulator.plant import Plant
from drivebench.transport.bus import BusSpec, open_bus
from drivebench.web.problems import problem_body
from tests.conftest import wait_for_value

SESSION = "demo-plant"
GERMAN = {"Accept-Language": "de-DE,de;q=0.9"}
HTMX = {"HX-Request": "true", "X-DriveBench": "1"}
FAULTS = f"/api/sessions/{SESSION}/simulator/nodes/5/faults"


def test_a_cia301_abort_text_is_german_and_a_manuals_own_text_stays_as_printed(client: TestClient) -> None:
    missing = "/api/sessions/demo-plant/nodes/{node}/parameters/0x2FFF"
    german = client.get(missing.format(node=7), headers=GERMAN).json()  # generic CiA 402 servo: CiA 301's texts
    assert german["type"] == "/problems/sdo-abort-error" and german["abort_code"] == "0x06020000"
    assert german["abort_text"] == "Objekt existiert nicht im Objektverzeichnis"
    assert german["detail"] == ("Knoten 7: 0x2FFFsub0: SDO-Abbruch 0x06020000 Objekt existiert nicht im "
                                "Objektverzeichnis")
    english = client.get(missing.format(node=7)).json()
    assert english["detail"] == ("Node 7: 0x2FFFsub0: SDO abort 0x06020000 Object does not exist in the object "
                                 "dictionary")
    assert english["abort_text"] == "Object does not exist in the object dictionary"
    manual = client.get(missing.format(node=5), headers=GERMAN).json()  # the 8400 motec manual's wording
    assert manual["abort_text"] == "Object not listed in object directory"
    assert manual["detail"] == "Knoten 5: 0x2FFFsub0: SDO-Abbruch 0x06020000 Object not listed in object directory"


def test_the_parameters_tab_shows_a_cia301_abort_in_german(client: TestClient) -> None:
    """0x08000024 has no text in the 8400 motec manual: the row's error box shows CiA 301's, in German."""
    assert client.put(FAULTS, json={"abort_code": 0x08000024}).status_code == 200
    row = client.post(f"/ui/sessions/{SESSION}/nodes/5/parameters/C00061/read", headers={**GERMAN, **HTMX})
    assert row.status_code == 502, row.text
    assert "SDO-Übertragung abgebrochen" in row.text and "SDO-Abbruch 0x08000024 Keine Daten verfügbar" in row.text
    english = client.post(f"/ui/sessions/{SESSION}/nodes/5/parameters/C00061/read", headers=HTMX)
    assert "SDO abort 0x08000024 No data available" in english.text


@pytest.mark.parametrize(("faults", "german", "english"), [
    pytest.param({"silent_after_segments": 1},
                 "Knoten 5 hat während einer segmentierten Übertragung von C00099 nach 1 von 2 Segmenten aufgehört "
                 "zu antworten",
                 "Node 5 stopped answering during a segmented transfer of C00099 after 1 of 2 segments", id="stalled"),
    pytest.param({"wrong_toggle": True},
                 "Knoten 5: Toggle-Bit-Fehler: Der Knoten hat während der segmentierten Übertragung von 0x5F9C sub 0 "
                 "(C00099) aus dem Takt geantwortet",
                 "Node 5: toggle bit error: the node answered out of step during the segmented transfer of "
                 "0x5F9C sub 0 (C00099)", id="toggle"),
])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_transfer_that_goes_wrong_is_told_in_german(client: TestClient, faults: dict[str, Any], german: str,
                                                      english: str) -> None:
    assert client.put(FAULTS, json=faults).status_code == 200
    url = f"/api/sessions/{SESSION}/nodes/5/parameters/C00099"
    read = client.get(url, headers=GERMAN).json()
    assert read["detail"] == german, read
    assert read["hint"].startswith(("Der Knoten hat auf den Beginn der Übertragung geantwortet",
                                    "Ein weiterer SDO-Client auf demselben Kanal"))
    assert client.get(url).json()["detail"] == english


def test_emcy_classes_and_register_bits_in_german_the_manuals_text_as_printed(client: TestClient) -> None:
    plant: Plant = client.app.state.drivebench.plants[SESSION]  # type: ignore[attr-defined]
    plant.nodes[5].raise_emcy(0x3100, register=0x05)
    url = f"/api/sessions/{SESSION}/nodes/5/emcy"
    german = wait_for_value(lambda: client.get(url, headers=GERMAN).json(), what="the EMCY")[0]
    assert german["class_text"] == "Netzspannung"  # CiA 301: 0x31xx
    assert german["register_bits"] == ["Allgemeiner Fehler", "Spannung"]
    assert german["vendor_text"].startswith("Supply voltage of standard device")  # the manual's words
    english = client.get(url).json()[0]
    assert english["class_text"] == "Mains voltage" and english["register_bits"] == ["Generic error", "Voltage"]
    tab = client.get(f"/ui/sessions/{SESSION}/nodes/5/diagnostics", headers={**GERMAN, **HTMX}).text
    assert "<td>Netzspannung</td>" in tab and "Allgemeiner Fehler, Spannung" in tab


def test_adapter_errors_and_their_hints_in_german(client: TestClient) -> None:
    unknown = client.post("/api/sessions", json={"bus": "nosuch:x@500000"}, headers=GERMAN).json()
    assert unknown["title"] == "CAN-Adapter nicht verfügbar"
    assert unknown["detail"] == "Unbekannte CAN-Schnittstelle 'nosuch'."
    assert unknown["hint"].startswith("python-can kennt: ")
    gateway = client.post("/api/sessions", json={"bus": "socketcand:127.0.0.1:9/can0"}, headers=GERMAN).json()
    assert gateway["detail"].startswith("Das socketcand-Gateway unter 127.0.0.1:9 ist nicht erreichbar: ")
    assert gateway["hint"] == ("Lauscht ein socketcand-Gateway unter 127.0.0.1:9, und bedient es den Kanal 'can0'? "
                               "Für einen lokalen Testbus starten Sie 'drivebench hub --port 9'.")
    english = client.post("/api/sessions", json={"bus": "socketcand:127.0.0.1:9/can0"}).json()
    assert english["hint"].startswith("Is a socketcand gateway listening at 127.0.0.1:9")
    malformed = client.post("/api/sessions", json={"bus": "can0"}, headers=GERMAN).json()
    assert malformed["detail"].startswith("'can0' ist keine Busangabe. Schreiben Sie INTERFACE:KANAL@BITRATE")


@pytest.fixture
def network(plant: Plant, channel: str) -> Iterator[CanopenNetwork]:
    master = CanopenNetwork(open_bus(BusSpec.parse(f"virtual:{channel}@500000")), sdo_timeout_s=0.2, sdo_retries=0)
    yield master
    master.close()


def test_an_error_raised_in_a_bus_thread_is_told_in_each_readers_language(network: CanopenNetwork) -> None:
    """Raised where no request says a language (a worker thread, while the test speaks German): the error keeps
    English in ``detail`` and its words for each reader of the problem."""
    caught: list[DriveBenchError] = []

    def work() -> None:
        for node, index in ((7, 0x2FFF), (40, 0x1000)):  # an abort (CiA 301 text), and silence (no node 40)
            try:
                network.node(node).upload(index, 0)
            except DriveBenchError as exc:
                caught.append(exc)

    with i18n.using("de"):
        worker = threading.Thread(target=work)
        worker.start()
        worker.join()
    aborted, silent = caught
    assert aborted.detail == "Node 7: 0x2FFFsub0: SDO abort 0x06020000 Object does not exist in the object dictionary"
    assert silent.detail == "Node 40 did not answer the SDO request for 0x1000sub0 (No SDO response received)"
    with i18n.using("de"):
        german, quiet = problem_body(aborted, "/x"), problem_body(silent, "/x")
    assert german["abort_text"] == "Objekt existiert nicht im Objektverzeichnis"
    assert quiet["detail"] == ("Knoten 40 hat auf die SDO-Anfrage für 0x1000sub0 nicht geantwortet "
                               "(keine SDO-Antwort erhalten)")
    assert str(quiet["hint"]).startswith("Prüfen Sie, ob der Knoten Spannung hat")
    with i18n.using("en"):
        assert problem_body(aborted, "/x")["abort_text"] == "Object does not exist in the object dictionary"
        assert problem_body(silent, "/x")["detail"] == silent.detail
