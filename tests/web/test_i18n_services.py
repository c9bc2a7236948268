"""German answers of the application services through the real HTTP API: a parameter-set download's verification
message and job texts (made once by the job, read later by each reader in their language), set-file import
refusals, account and sign-in refusals, the bus state's sentence (made once, worded for each reader); English stays
as it was for everyone else."""

from __future__ import annotations

import json
import time
from typing import Any

from fastapi.testclient import TestClient

from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from tests.confirming import confirmed
from tests.conftest import wait_until
from tests.web.test_parameter_sets_api import finish

SESSION = "demo-plant"
SETS = "/api/parameter-sets"
GERMAN = {"Accept-Language": "de-DE,de;q=0.9"}
ENGLISH = {"Accept-Language": "en"}


def test_a_download_says_its_verification_and_progress_in_each_readers_language(demo_api: TestClient) -> None:
    uploaded = finish(demo_api, demo_api.post(f"{SETS}/upload",
                                              json={"session_id": SESSION, "node_id": 5, "name": "Band"},
                                              headers=GERMAN).json())
    assert uploaded["title"] == "Upload node 5 into 'Band'"  # started by a German reader, read by an English one
    exported = json.loads(demo_api.get(f"{SETS}/{uploaded['set_id']}/export").text)
    for parameter in exported["parameters"]:
        if parameter["ref"] == "C00088":
            parameter["value"] = 12.34
    set_id = demo_api.post(f"{SETS}/import",
                           files={"file": ("c.json", json.dumps(exported).encode())}).json()["set"]["id"]
    # the drive keeps C00088 in 0.1 A steps: the write goes in, the read-back differs
    store = demo_api.app.state.drivebench.plants[SESSION].nodes[5].store  # type: ignore[attr-defined]
    store.add_write_hook(lambda index, sub, raw: store.set(index, sub, raw // 10 * 10, notify=False)
                         if (index, sub) == (0x5FA7, 0) else None)

    started = confirmed(demo_api, "POST", f"{SETS}/{set_id}/download",
                        json={"session_id": SESSION, "node_id": 5, "confirm": 5},
                        headers=GERMAN)  # started by a German reader: the job itself speaks no one's language
    assert started.status_code == 202, started.text
    job_id = finish(demo_api, started.json())["id"]

    german = demo_api.get(f"{SETS}/jobs/{job_id}", headers=GERMAN).json()
    english = demo_api.get(f"{SETS}/jobs/{job_id}", headers=ENGLISH).json()
    assert german["download_state"] == "incomplete", german
    assert german["title"] == "'Band' auf Knoten 5 übertragen"
    assert english["title"] == "Download 'Band' to node 5"
    german_line = next(line for line in german["report"] if line["ref"] == "C00088")
    english_line = next(line for line in english["report"] if line["ref"] == "C00088")
    assert german_line["status"] == english_line["status"] == "mismatch"  # what scripts read never changes
    assert german_line["detail"] == "12.34 A geschrieben, das Gerät meldet 12.30 A"
    assert english_line["detail"] == "Wrote 12.34 A, the device reports 12.30 A"
    assert [i["detail"] for i in demo_api.get(f"/api/jobs/{job_id}", headers=GERMAN).json()["issues"]] == \
        ["12.34 A geschrieben, das Gerät meldet 12.30 A"]

    # the report as stored in the database, read later (by another server too) in each reader's language
    stored = f"/api/parameter-downloads/{german['download_id']}"
    assert next(line["detail"] for line in demo_api.get(stored, headers=GERMAN).json()["report"]
                if line["ref"] == "C00088") == "12.34 A geschrieben, das Gerät meldet 12.30 A"
    assert next(line["detail"] for line in demo_api.get(stored).json()["report"]
                if line["ref"] == "C00088") == "Wrote 12.34 A, the device reports 12.30 A"
    page = demo_api.get(f"/parameter-sets/downloads/{german['download_id']}", headers=GERMAN).text
    assert "12.34 A geschrieben, das Gerät meldet 12.30 A" in page and "Wrote 12.34 A" not in page

    nothing = demo_api.post(f"/api/parameter-downloads/{german['download_id']}/rollback", headers=GERMAN, json={})
    assert nothing.status_code == 202  # C00088 changed: it can be rolled back
    back = finish(demo_api, nothing.json())
    assert demo_api.get(f"{SETS}/jobs/{back['id']}", headers=GERMAN).json()["title"] == \
        f"Download {german['download_id']} auf Knoten 5 zurückrollen"


def test_an_import_refusal_and_set_errors_in_german(demo_api: TestClient) -> None:
    csv = b"C00088,Rated motor current,1,A\n"
    form = {"profile_id": "lenze-8400-motec-canopen"}
    german = demo_api.post(f"{SETS}/import", files={"file": ("bad.csv", csv)}, data=form, headers=GERMAN)
    assert german.status_code == 422 and german.json()["title"] == "Parametersatz-Datei passt nicht"
    assert german.json()["detail"] == "bad.csv: 1 Wert passt nicht: Zeile 1: Kopfzeile 'code,name,value,unit' erwartet"
    assert german.json()["errors"] == [{"line": 1, "ref": None,
                                        "detail": "Kopfzeile 'code,name,value,unit' erwartet"}]
    english = demo_api.post(f"{SETS}/import", files={"file": ("bad.csv", csv)}, data=form)
    assert english.json()["detail"] == "bad.csv: 1 value does not fit: line 1: expected a header line " \
                                       "'code,name,value,unit'"
    assert demo_api.get(f"{SETS}/4711", headers=GERMAN).json()["detail"] == "Kein Parametersatz 4711"
    unknown = demo_api.get(f"{SETS}/4711/export", params={"format": "json"}, headers=GERMAN)
    assert unknown.status_code == 404 and unknown.json()["detail"] == "Kein Parametersatz 4711"


def test_account_refusals_in_german(demo_api: TestClient) -> None:
    accounts.create_user("root", "root password", Role.ADMIN)
    accounts.create_user("eve", "engineer password", Role.ENGINEER)
    root = {"Authorization": f"Bearer {accounts.issue_token('root', 'test', Role.ADMIN).secret}"}
    eve = {"Authorization": f"Bearer {accounts.issue_token('eve', 'test', Role.ENGINEER).secret}"}

    disabled = demo_api.patch("/api/users/eve", json={"disabled": True}, headers=root)
    assert disabled.status_code == 200 and disabled.json()["disabled"] is True, disabled.text
    signing_in = demo_api.post("/api/auth/login", json={"name": "eve", "password": "engineer password"}, headers=GERMAN)
    assert signing_in.status_code == 401
    assert signing_in.json()["detail"] == "Falscher Benutzername oder falsches Passwort."
    assert demo_api.post("/api/auth/login", json={"name": "eve", "password": "engineer password"}).json()["detail"] == \
        "Wrong user name or password."
    token = demo_api.get("/api/sessions", headers={**eve, **GERMAN})  # a disabled user's token stopped working
    assert token.status_code == 401
    assert token.json()["detail"] == "Das API-Token ist unbekannt oder widerrufen."
    assert token.json()["hint"].startswith("Erstellen Sie ein neues Token auf der Seite Benutzer")

    last = demo_api.patch("/api/users/root", json={"disabled": True}, headers={**root, **GERMAN})
    assert last.status_code == 409
    assert last.json()["detail"].startswith("root ist der letzte aktive Admin: Ohne ihn wäre die Anmeldung")
    assert last.json()["hint"] == "Legen Sie zuerst einen weiteren Admin an."
    short = demo_api.post("/api/users", json={"name": "otto", "password": "kurz", "role": "viewer"},
                          headers={**root, **GERMAN})
    assert short.status_code == 422
    missing = demo_api.get("/api/users/nobody", headers={**root, **GERMAN})
    assert missing.status_code == 404 and missing.json()["detail"] == "Es gibt keinen Benutzer namens nobody."
    assert demo_api.get("/api/users/nobody", headers=root).json()["detail"] == "There is no user called nobody."


def test_a_sign_in_lock_counts_down_in_german(demo_api: TestClient) -> None:
    accounts.create_user("root", "root password", Role.ADMIN)
    for _attempt in range(5):
        demo_api.post("/api/auth/login", json={"name": "root", "password": "wrong"})
    locked = demo_api.post("/api/auth/login", json={"name": "root", "password": "wrong"}, headers=GERMAN)
    assert locked.status_code == 429
    detail = locked.json()["detail"]
    assert detail.startswith("Zu viele fehlgeschlagene Anmeldungen für root: Versuchen Sie es in ")
    assert detail.endswith(" Sekunden erneut.") or detail.endswith(" Sekunde erneut.")
    assert locked.json()["hint"].startswith("Warten Sie und melden Sie sich dann erneut an")


def _bus_text_of_an_update(socket: Any, timeout_s: float = 10.0) -> str:
    """The bus sentence of the first update a monitor websocket sends with one (not its hello)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = json.loads(socket.receive_text())
        if message["type"] == "update" and message["snapshot"]["bus_text"]:
            return str(message["snapshot"]["bus_text"])
    raise AssertionError("no monitor update said how the bus is")


def test_the_bus_sentence_is_made_once_and_worded_for_each_reader(demo_api: TestClient) -> None:
    """A lost adapter in the words of each reader: the session API, the Plant page, the REST monitor frozen by an
    English reader's pause and read by a German one, and two viewers of one monitor feed."""
    session = f"/api/sessions/{SESSION}"
    adapter = demo_api.app.state.drivebench.manager.get(SESSION).network.bus.adapter  # type: ignore[attr-defined]
    adapter.unplug()
    try:
        assert wait_until(lambda: "reconnecting" in (demo_api.get(session).json()["state_text"] or ""))
        assert demo_api.get(session).json()["state_text"].startswith("adapter lost: USB adapter unplugged since ")
        worded = demo_api.get(session, headers=GERMAN).json()["state_text"]
        assert worded.startswith("Adapter verloren: USB-Adapter abgezogen seit ") and "; verbindet neu" in worded
        assert "Adapter verloren: USB-Adapter abgezogen seit " in demo_api.get("/", headers=GERMAN).text

        assert demo_api.post(f"{session}/monitor/pause", headers=ENGLISH).json() == {"paused": True}
        frozen = demo_api.get(f"{session}/monitor?trace=0", headers=GERMAN).json()
        assert frozen["paused"] and frozen["bus_text"].startswith("Adapter verloren: USB-Adapter abgezogen seit ")
        assert demo_api.post(f"{session}/monitor/resume").json() == {"paused": False}

        url = f"/ws/sessions/{SESSION}/monitor?rows=1"
        with demo_api.websocket_connect(url, headers=GERMAN) as german, demo_api.websocket_connect(url) as english:
            assert _bus_text_of_an_update(german).startswith("Adapter verloren: USB-Adapter abgezogen seit ")
            assert _bus_text_of_an_update(english).startswith("adapter lost: USB adapter unplugged since ")
    finally:
        adapter.plug_in()
