"""Stored scope recordings (issue 31 item 4): the packed samples read back exactly (gaps stay gaps), with their
channels, trigger, markers and the nodes' parameter-set reference; in SQLite and PostgreSQL, through the migration."""

from __future__ import annotations

import math

import pytest

from drivebench.config import settings
from drivebench.errors import NotFound
from drivebench.i18n import N_, Text, using
from drivebench.protocol.canopen.network import CANNOT_SEND
from drivebench.services.scope import export, store
from drivebench.services.storage import database


def _recording(count: int, channels: int) -> store.Recording:
    values: list[list[float | None]] = [[math.sin(n / 100 + c) * 1000 for n in range(count)] for c in range(channels)]
    values[0][3] = None  # the node sent nothing for this sample
    columns = store.Columns(list(range(7, 7 + count)), [n * 0.001 for n in range(count)], values)
    return store.Recording("before the change", "demo-plant", "eve", "sdo-poll", 0.001,
                           [{"node": 3, "ref": f"0x60{c:02X}", "bit": None, "name": f"ch {c}", "unit": "rpm",
                             "label": f"3: ch {c}"} for c in range(channels)],
                           {"mode": "single", "position": 2}, [{"time_s": 0.002, "node": 3, "kind": "emcy",
                                                                "text": "EMCY 2310h"}],
                           {"3": {"profile_id": "siemens-micromaster4-canopen", "parameter_set_id": None}}, columns)


def test_pack_and_unpack_keep_every_value_and_every_gap() -> None:
    recording = _recording(1000, 3)
    back = store.unpack(store.pack(recording.columns), 1000, 3)
    assert back == recording.columns and back.values[0][3] is None


def test_a_recording_is_stored_listed_loaded_and_deleted(database_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "database_url", database_url)
    database.upgrade_to_head(database_url)
    recording = _recording(100_000, 8)
    recording_id = store.save(recording)
    listed = store.listing()
    assert [(r["id"], r["name"], r["count"]) for r in listed] == [(recording_id, "before the change", 100_000)]
    back = store.load(recording_id)
    assert back.columns == recording.columns
    assert (back.trigger, back.markers, back.nodes) == (recording.trigger, recording.markers, recording.nodes)
    text = export.to_csv(back).splitlines()
    assert text[0] == "sample,time_s," + ",".join(f"3: ch {c} [rpm]" for c in range(8))
    assert text[4].split(",")[:3] == ["10", "0.003000", ""], "a gap is an empty CSV field"
    store.remove(recording_id)
    with pytest.raises(NotFound, match="no scope recording"):
        store.load(recording_id)
    with pytest.raises(NotFound):
        store.remove(recording_id)


def test_a_marker_kept_as_text_is_read_in_each_language_and_an_old_plain_one_as_it_was(
        database_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(settings, "database_url", database_url)
    database.upgrade_to_head(database_url)
    recording = _recording(10, 1)  # its EMCY marker is a plain text, as every row stored before Texts
    bus_off = Text(N_("The CAN adapter is bus-off: no frames are sent or received."))
    silent = Text(N_("Node {node} stopped sending its TPDOs (none for {ms} ms): its channels are empty from here."),
                  node=7, ms="1020")
    lost = Text(N_("SYNC lost: DriveBench could not send it ({why}). The recording receives no more samples."),
                why=Text(CANNOT_SEND, bus="virtual:x", reason=OSError("unplugged")))  # an error's detail holds it
    recording.markers += [store.marker(0.004, None, "source", bus_off), store.marker(0.005, 7, "source", silent),
                          store.marker(0.006, None, "source", lost)]
    back = store.load(store.save(recording))
    with using("de"):
        german = [m["text"] for m in back.as_json()["markers"]]
    with using("en"):
        english = back.as_json()["markers"]
    assert german == ["EMCY 2310h", "Der CAN-Adapter ist Bus-Off: es werden keine Telegramme gesendet oder empfangen.",
                      "Knoten 7 sendet seine TPDOs nicht mehr (keines seit 1020 ms): seine Kanäle sind ab hier leer.",
                      "SYNC verloren: DriveBench konnte es nicht senden (Senden auf virtual:x nicht möglich: "
                      "unplugged). Die Aufzeichnung erhält keine Abtastwerte mehr."]
    assert [m["text"] for m in english] == ["EMCY 2310h", str(bus_off), str(silent), str(lost)]
    assert english[2] == {"time_s": 0.005, "node": 7, "kind": "source", "text": str(silent)}, \
        "a reader gets the text, not the form it is kept in"
    assert back.markers[1]["text"] == "The CAN adapter is bus-off: no frames are sent or received.", \
        "the row keeps the English text for readers that know no template"
