"""The device layer in German over the real HTTP API: EDS/DCF/JSON import warnings and refusals, load errors of files
read at start, the batch-upload summary and the calculators answer a German browser in German and everyone else in
the unchanged English. Warnings stored with a profile keep their template: each reader gets them in their language."""

from __future__ import annotations

import copy
import io
import json
import pickle
import zipfile
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.i18n import N_, Text, shown, using
from drivebench.web.app import create_app
from tests.device.quirk_corpus import CORPUS_FILES
from tests.web.test_profiles_api import MOTEC, SERVO_EDS, broken_servo_eds

GERMAN = {"Accept-Language": "de-DE,de;q=0.9,en;q=0.5"}


def test_a_text_keeps_its_template_and_is_shown_in_the_readers_language() -> None:
    inner = Text(N_("{text!r} is not a number"), text="x1")
    joined = Text.joined("; ", [Text(N_("{reason}: dropped"), reason=inner), "plain"])
    assert joined == "'x1' is not a number: dropped; plain"  # the string itself is the English text
    with using("de"):
        assert shown(joined) == "'x1' ist keine Zahl: verworfen; plain"
        assert shown("any other string") == "any other string"
    assert shown(joined) == joined
    for copied in (copy.deepcopy(joined), pickle.loads(pickle.dumps(joined))):
        assert copied == joined and copied.template == joined.template
        with using("de"):
            assert shown(copied) == "'x1' ist keine Zahl: verworfen; plain"
    braces = Text(N_("may use {names} only"), names="{ref}")  # the English text holds braces of its own
    assert copy.copy(braces) == "may use {ref} only"


def test_an_eds_quirk_is_warned_in_the_language_of_each_reader(api: TestClient) -> None:
    name, content, _case = next(f for f in CORPUS_FILES if "default-octal-leading-zero" in f[0])
    uploaded = api.post("/api/profiles", files={"file": (name, content)}, headers=GERMAN)
    assert uploaded.status_code == 201, uploaded.text
    german = [w["message"] for w in uploaded.json()["warnings"]]
    assert "'0100': als Oktalzahl 64 gelesen (CiA 306: eine führende 0 bedeutet oktal), nicht dezimal 100" in german
    profile_id = uploaded.json()["id"]
    english = [w["message"] for w in api.get(f"/api/profiles/{profile_id}/warnings").json()]
    assert "'0100': read as octal 64 (CiA 306: a leading 0 means octal), not decimal 100" in english
    assert api.get(f"/api/profiles/{profile_id}/warnings", headers=GERMAN).json()[0]["message"] in german
    page = api.get(f"/profiles/{profile_id}", headers=GERMAN).text  # the Profiles page lists them too
    assert "als Oktalzahl 64 gelesen" in page and "read as octal" not in page


def test_every_quirk_of_the_corpus_is_warned_in_german(api: TestClient) -> None:
    for name, content, _case in CORPUS_FILES:
        uploaded = api.post("/api/profiles", files={"file": (name, content)}, headers=GERMAN)
        assert uploaded.status_code == 201, (name, uploaded.text)
        german = [w["message"] for w in uploaded.json()["warnings"]]
        english = [w["message"] for w in api.get(f"/api/profiles/{uploaded.json()['id']}/warnings").json()]
        assert len(german) == len(english)
        assert not [text for text in german if text in english], name  # every one is German, none left English


def test_a_file_that_did_not_load_at_start_is_reported_in_german(user_dir: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    user_dir.mkdir()
    (user_dir / "bad.eds").write_bytes(broken_servo_eds(41))
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:  # read at start, outside any request
        german = client.get("/api/profiles/load-errors", headers=GERMAN).json()
        assert german == [{"file": "bad.eds", "line": 41,
                           "reason": "Binärmüll (Steuerzeichen) statt EDS-Text und kein Objektabschnitt"}]
        assert client.get("/api/profiles/load-errors").json()[0]["reason"] == (
            "binary junk (control characters) instead of EDS text, and no object section")
        assert "Binärmüll (Steuerzeichen)" in client.get("/profiles", headers=GERMAN).text


def test_refused_uploads_say_why_in_german(api: TestClient) -> None:
    broken = api.post("/api/profiles", files={"file": ("broken.eds", broken_servo_eds(41))}, headers=GERMAN)
    assert broken.status_code == 422
    assert broken.json()["detail"] == "broken.eds:41: Binärmüll (Steuerzeichen) statt EDS-Text und kein Objektabschnitt"
    profile = json.loads((REPO_ROOT / "device_profiles" / f"{MOTEC}.json").read_text())
    profile["id"] = "motec-copy"
    profile["parameters"][0].update({"min": 10, "max": 1})
    invalid = api.post("/api/profiles", files={"file": ("copy.json", json.dumps(profile, indent=1).encode())},
                       headers=GERMAN)
    assert invalid.status_code == 422, invalid.text
    assert "ist größer als max 1" in invalid.json()["detail"]  # a validator of the profile model, in German
    english = api.post("/api/profiles", files={"file": ("copy.json", json.dumps(profile, indent=1).encode())})
    assert "is greater than max 1" in english.json()["detail"]
    wrong_type = api.post("/api/profiles", files={"file": ("servo.txt", SERVO_EDS.read_bytes())}, headers=GERMAN)
    assert wrong_type.json()["detail"] == ("servo.txt: unbekannter Profildateityp .txt; verwenden Sie .json, .eds, "
                                           ".dcf, .xdd oder .xdc; dies sieht wie eine EDS aus, benennen Sie die "
                                           "Datei .eds")
    built_in = api.delete(f"/api/profiles/{MOTEC}", headers=GERMAN)
    assert built_in.status_code == 409 and "ist ein mitgeliefertes Profil" in built_in.json()["detail"]


def test_the_batch_summary_gives_its_reasons_in_german(api: TestClient) -> None:
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w") as zipped:
        zipped.writestr("../../outside.eds", SERVO_EDS.read_bytes())
    files = [("files", ("vendor.zip", archive.getvalue())), ("files", ("broken.eds", broken_servo_eds(41)))]
    rows = {r["file"]: r for r in api.post("/api/profiles/batch", files=files, headers=GERMAN).json()["rows"]}
    assert rows["vendor.zip/../../outside.eds"]["reason"] == ("Sein Pfad verlässt das Archiv (absolut oder mit "
                                                              "'..'): nicht gelesen")
    assert rows["broken.eds"]["reason"] == "Binärmüll (Steuerzeichen) statt EDS-Text und kein Objektabschnitt"
    assert rows["broken.eds"]["line"] == 41


def test_the_calculators_answer_in_german(api: TestClient) -> None:
    bad = api.get("/api/tools/dip/lenze-8400-motec", params={"node_id": 64, "baud_kbit": 500}, headers=GERMAN)
    assert bad.status_code == 422 and "Knotennummer 64 liegt außerhalb von 1 … 63" in bad.json()["detail"]
    decoded = api.get("/api/tools/dip/lenze-emf2178ib", params={"on": "S1"}, headers=GERMAN).json()
    assert decoded["result"]["summary"].startswith("Knotennummer 64 (aus den Schaltern), Baudrate ")
    cable = api.get("/api/tools/cable", params={"baud_kbit": 125, "nodes": 28, "length_m": 450,
                                                "cross_section_mm2": 0.5}, headers=GERMAN).json()
    assert cable["steps"][0] == "1. Gesamte Leitungslänge bei 125 kbit/s: 600 m (Tabelle [5-1])."
    english = api.get("/api/tools/cable", params={"baud_kbit": 125, "nodes": 28, "length_m": 450,
                                                  "cross_section_mm2": 0.5}).json()
    assert english["steps"][0] == "1. Total cable length at 125 kbit/s: 600 m (table [5-1])."
    tables = api.get("/api/tools/cable/tables", headers=GERMAN).json()["selection_example"]
    assert tables["note"].startswith("Wie in §5.2.4 abgedruckt.") and tables["given"].startswith("0,5 mm², 63 Knoten")
    assert "Wie in §5.2.4 abgedruckt." in api.get("/tools", headers=GERMAN).text
    unlisted = api.get("/api/tools/cable", params={"baud_kbit": 300, "nodes": 28, "length_m": 450,
                                                   "cross_section_mm2": 0.5}, headers=GERMAN)
    assert unlisted.status_code == 422 and unlisted.json()["detail"].startswith("300 kbit/s steht nicht in Tabelle")
    cobids = api.get("/api/tools/cobids", params={"family": "siemens-mm4", "node_id": 5, "pdo_ids": "lenze"},
                     headers=GERMAN)
    assert "sind keine Identifier 'lenze' festgelegt" in cobids.json()["detail"]
    form = api.post("/ui/tools/cable", data={"baud_kbit": "125", "cross_section_mm2": "0.5", "nodes": "many",
                                             "length_m": "450", "repeater_reduction_m": "30"},
                    headers={**GERMAN, "HX-Request": "true", "X-DriveBench": "1"})
    assert form.status_code == 422 and "Geben Sie ganze Zahlen für die Knoten" in form.text


def test_a_parameter_reference_that_is_none_is_refused_in_german(client: TestClient) -> None:
    wrong = client.get("/api/sessions/demo-plant/nodes/5/parameters/zz-top", headers=GERMAN)
    assert wrong.status_code == 404, wrong.text
    assert wrong.json()["detail"].startswith("'zz-top' ist keine Parameterangabe.")
    assert client.get("/api/sessions/demo-plant/nodes/5/parameters/zz-top").json()["detail"].startswith(
        "'zz-top' is not a parameter reference.")
