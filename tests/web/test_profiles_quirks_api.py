"""Quirky device descriptions through the real API: accepted with warnings[], the warnings stored with the profile
(also after a restart), the file downloads back byte for byte, and a refused file changes nothing. Many files at
once: a summary row per file, limits refused in words (zip bomb, paths leaving the archive, too many files),
/api/health answering while a large upload is checked."""

from __future__ import annotations

import difflib
import html
import io
import re
import threading
import time
import zipfile
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivebench.config import REPO_ROOT
from drivebench.config import settings as app_settings
from drivebench.device.profiles.profile_batch import MAX_FILES
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, serve_app
from tests.device.quirk_corpus import BASE, CORPUS_FILES

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_every_corpus_file_uploads_with_its_warnings_and_downloads_byte_identical(api: TestClient,
                                                                                   user_dir: Path) -> None:
    for name, content, case in CORPUS_FILES:
        response = api.post("/api/profiles", files={"file": (name, content)})
        assert response.status_code == 201, (name, response.text)
        body = response.json()
        messages = [w["message"] for w in body["warnings"]]
        assert body["warning_count"] == len(messages)
        if case.warns is None:
            assert messages == [], name
        else:
            assert any(case.warns in m for m in messages), (name, messages)
            assert all(w["file"] == name for w in body["warnings"])
        download = api.get(f"/api/profiles/{body['id']}/eds")
        assert download.status_code == 200 and download.content == content, name
        assert download.headers["content-disposition"].endswith(f'{case.suffix}"')
        assert api.get(f"/api/profiles/{body['id']}/warnings").json() == body["warnings"]
    listed = {p["id"]: p["warning_count"] for p in api.get("/api/profiles").json()}
    assert sum(1 for _, _, case in CORPUS_FILES if case.warns) <= sum(1 for n in listed.values() if n)


def test_warnings_survive_a_restart_and_limit_notes_reach_the_rows(user_dir: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    name, content, _ = next(f for f in CORPUS_FILES if "signed-limits-on-unsigned32" in f[0])
    monkeypatch.setattr(app_settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        profile_id = client.post("/api/profiles", files={"file": (name, content)}).json()["id"]
    with TestClient(create_app()) as client:  # read again from the upload folder
        warnings = client.get(f"/api/profiles/{profile_id}/warnings").json()
        assert [w["object"] for w in warnings if w["limits"]] == ["0x2000sub0"]
        row = client.get(f"/api/profiles/{profile_id}/parameters", params={"q": "0x2000"}).json()["items"][0]
        assert row["min"] is None and row["max"] is None
        assert "limits dropped: LowLimit 0x80000000 > HighLimit 0x7FFFFFFF" in row["limits_note"]
        regenerated = client.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"})
        assert regenerated.content == content  # unedited: written over the file, nothing differs (issue 34)


def test_a_file_without_object_dictionary_is_refused_and_nothing_is_lost(api: TestClient) -> None:
    name, content, _ = CORPUS_FILES[0]
    kept = api.post("/api/profiles", files={"file": (name, content)}).json()["id"]
    before = api.get("/api/profiles").json()
    for junk in (b"\x00\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, b"", b"[FileInfo]\nFileName=x.eds\n",
                 content[:300]):
        refused = api.post("/api/profiles", files={"file": ("junk.eds", junk)})
        assert refused.status_code == 422, refused.text
        assert refused.headers["content-type"].startswith("application/problem+json")
        assert refused.json()["source"] == "junk.eds" and "object" in refused.json()["detail"]
    assert api.get("/api/profiles").json() == before
    assert api.get(f"/api/profiles/{kept}/eds").content == content


def corpus_file(case_name: str) -> tuple[str, bytes]:
    name, content, _ = next(f for f in CORPUS_FILES if f[2].name == case_name)
    return name, content


def uploaded_row(api: TestClient, case_name: str, ref: str) -> dict[str, object]:
    name, content = corpus_file(case_name)
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    items = api.get(f"/api/profiles/{response.json()['id']}/parameters", params={"q": ref}).json()["items"]
    return next(row for row in items if row["ref"] == ref)


def test_a_var_with_a_stray_sub0_section_stays_a_var(api: TestClient) -> None:
    row = uploaded_row(api, "var-with-stray-sub0", "0x100B")
    assert (row["data_type"], row["access"], row["subindex"], row["default"]) == ("UNSIGNED8", "rw", 0, 0x7F)


def test_access_type_with_a_hash_comment_is_read_without_it(api: TestClient) -> None:
    row = uploaded_row(api, "access-type-hash-comment", "0x2000")
    assert (row["data_type"], row["access"]) == ("UNSIGNED32", "rw")


@pytest.mark.parametrize("case_name", ["utf16-le-bom", "utf16-le-no-bom", "utf16-be-no-bom", "utf32-le-bom"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_utf16_or_utf32_eds_reads_like_its_utf8_twin(api: TestClient, case_name: str) -> None:
    name, content = corpus_file(case_name)
    wide = api.post("/api/profiles", files={"file": (name, content)})
    assert wide.status_code == 201, wide.text
    assert wide.json()["warnings"] == []
    twin = api.post("/api/profiles", files={"file": ("twin.eds", BASE.encode())}).json()
    assert (wide.json()["objects"], wide.json()["parameters"]) == (twin["objects"], twin["parameters"])
    vendor = "M\u00fcller Antriebe" if case_name == "utf16-be-no-bom" else "Example Drives"
    assert wide.json()["vendor"] == vendor


XDD_DIR = Path(__file__).resolve().parents[1] / "data" / "xdd"


@pytest.mark.parametrize("name", sorted(p.name for p in XDD_DIR.iterdir()))
def test_xdd_and_xdc_upload_and_download_byte_identical(api: TestClient, name: str) -> None:
    content = (XDD_DIR / name).read_bytes()
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert response.status_code == 201, response.text
    profile_id = response.json()["id"]
    original = api.get(f"/api/profiles/{profile_id}/xdd")
    assert original.content == content and original.headers["content-type"].startswith("application/xml")
    written = api.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    assert written == content  # written over the upload: unedited, it is the upload (issue 34)
    as_eds = api.get(f"/api/profiles/{profile_id}/eds").content
    again_eds = api.post("/api/profiles", files={"file": ("again.eds", as_eds)})
    # the EDS export adds the CiA 301 mandatory objects a file lacks (quirks.xdd has no 0x1001, 0x1018)
    assert again_eds.status_code == 201 and again_eds.json()["objects"] >= response.json()["objects"]
    objects = api.get(f"/api/profiles/{profile_id}").json()["objects"]
    addresses = {(o["index"], o["subindex"]) for o in objects}
    kept = api.get(f"/api/profiles/{again_eds.json()['id']}").json()["objects"]
    assert [(o["index"], o["subindex"], o["default"]) for o in kept if (o["index"], o["subindex"]) in addresses] == [
        (o["index"], o["subindex"], o["default"]) for o in objects]


def test_unsafe_xml_upload_is_a_problem_in_words(api: TestClient) -> None:
    before = api.get("/api/profiles").json()
    xxe = b'<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n<x>&e;</x>'
    refused = api.post("/api/profiles", files={"file": ("evil.xdd", xxe)})
    assert refused.status_code == 422
    assert (refused.json()["source"], refused.json()["line"]) == ("evil.xdd", 2)
    assert "DOCTYPE" in refused.json()["detail"] and "passwd" not in refused.text.replace("file:///etc/passwd", "")
    assert api.get("/api/profiles").json() == before


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-32-be"])
def test_unsafe_xml_in_utf16_or_utf32_is_refused_too(api: TestClient, encoding: str) -> None:
    before = api.get("/api/profiles").json()
    xxe = '<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n<x>&e;</x>'
    refused = api.post("/api/profiles", files={"file": ("evil.xdd", xxe.encode(encoding))})
    assert refused.status_code == 422
    assert (refused.json()["source"], refused.json()["line"]) == ("evil.xdd", 2)
    assert "DOCTYPE" in refused.json()["detail"]
    assert api.get("/api/profiles").json() == before


# --- many files at once, bad input ------------------------------------------------------------------------
def make_zip(members: list[tuple[str, bytes]]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, content in members:
            archive.writestr(name, content)
    return buffer.getvalue()


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_vendor_folder_zip_gives_one_row_per_file(api: TestClient, user_dir: Path) -> None:
    members = [(f"Vendor/EDS/{name}", content) for name, content, _ in CORPUS_FILES]
    members += [("Vendor/readme.txt", b"not a profile"), ("Vendor/EDS/broken.eds", b"[FileInfo]\nFileName=b\n"),
                ("../../outside.eds", BASE.encode()), ("Vendor/big.eds", b"\0" * (4 * 1024 * 1024))]
    response = api.post("/api/profiles/batch", files={"files": ("vendor.zip", make_zip(members))})
    assert response.status_code == 200, response.text
    result = response.json()
    rows = {row["file"]: row for row in result["rows"]}
    assert result["accepted"] + result["with_warnings"] == len(CORPUS_FILES)
    assert result["with_warnings"] == sum(1 for _, _, case in CORPUS_FILES if case.warns)
    broken = rows["vendor.zip/Vendor/EDS/broken.eds"]
    assert (broken["outcome"], broken["line"]) == ("refused", 1) and "no object dictionary" in broken["reason"]
    assert "leaves the archive" in rows["vendor.zip/../../outside.eds"]["reason"]
    assert "zip bomb" in rows["vendor.zip/Vendor/big.eds"]["reason"]
    assert not any("readme" in name for name in rows)
    assert not (user_dir.parent / "outside.eds").exists()
    listed = {p["id"] for p in api.get("/api/profiles").json()}
    assert {row["profile_id"] for row in result["rows"] if row["profile_id"]} <= listed


def test_a_refused_zip_member_is_named_with_its_path_and_line(api: TestClient) -> None:
    xxe = '<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n<x>&e;</x>'
    members = [("Vendor/XML/evil.xdd", xxe.encode("utf-16")), ("Vendor/EDS/servo.eds", BASE.encode("utf-16-le"))]
    rows = api.post("/api/profiles/batch", files={"files": ("vendor.zip", make_zip(members))}).json()["rows"]
    by_name = {row["file"]: row for row in rows}
    evil = by_name["vendor.zip/Vendor/XML/evil.xdd"]
    assert (evil["outcome"], evil["line"]) == ("refused", 2) and "DOCTYPE" in evil["reason"]
    assert by_name["vendor.zip/Vendor/EDS/servo.eds"]["outcome"] == "accepted"


def test_several_files_at_once_and_limits_in_words(api: TestClient) -> None:
    (name, content, _), (other, second, _) = CORPUS_FILES[:2]
    response = api.post("/api/profiles/batch", files=[("files", (name, content)), ("files", (other, second)),
                                                      ("files", ("x.zip", b"PK not a zip"))])
    assert [row["outcome"] for row in response.json()["rows"]] == ["refused", "warnings", "warnings"]
    assert "not a readable zip archive" in response.json()["rows"][0]["reason"]
    before = api.get("/api/profiles").json()
    too_many = make_zip([(f"f{n}.eds", b"x") for n in range(MAX_FILES + 1)])
    refused = api.post("/api/profiles/batch", files={"files": ("many.zip", too_many)}).json()["rows"][0]
    assert refused["outcome"] == "refused" and f"at most {MAX_FILES}" in refused["reason"]
    parts = [("files", (f"f{n}.eds", b"x")) for n in range(MAX_FILES + 1)]
    problem = api.post("/api/profiles/batch", files=parts)
    assert problem.status_code == 422 and f"at most {MAX_FILES} files" in problem.json()["detail"]
    assert api.post("/api/profiles/batch", data={"x": "1"}).status_code == 422
    assert api.get("/api/profiles").json() == before


BAD_INPUT = [
    ("truncated.eds", BASE.encode()[:700], "no object dictionary"),
    ("random.eds", bytes(range(256)) * 64, "binary junk"),
    ("one-line.eds", b"[1000]" + b"x" * (5 * 1024 * 1024 - 10), None),
    ("nested.xdd", b"<ISO15745ProfileContainer>" + b"<a>" * 200_000 + b"</ISO15745ProfileContainer>", "XML"),
]


@pytest.mark.parametrize(("name", "content", "words"), BAD_INPUT, ids=[b[0] for b in BAD_INPUT])
def test_bad_input_is_a_clear_4xx_and_loses_nothing(api: TestClient, name: str, content: bytes,
                                                    words: str | None) -> None:
    kept_name, kept, _ = CORPUS_FILES[0]
    kept_id = api.post("/api/profiles", files={"file": (kept_name, kept)}).json()["id"]
    before = api.get("/api/profiles").json()
    response = api.post("/api/profiles", files={"file": (name, content)})
    assert 400 <= response.status_code < 500, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    assert response.json()["detail"] and (words is None or words in response.json()["detail"])
    assert api.get("/api/profiles").json() == before
    assert api.get(f"/api/profiles/{kept_id}/eds").content == kept


def test_100000_objects_load_or_are_refused_in_words(api: TestClient) -> None:
    sections = "".join(f"[{0x2000 + n // 256:04X}sub{n % 256:X}]\nParameterName=P{n}\nDataType=0x0007\n"
                       f"AccessType=rw\n" for n in range(100_000))
    heads = "".join(f"[{0x2000 + i:04X}]\nParameterName=R{i}\nObjectType=0x9\nSubNumber=256\n"
                    for i in range(100_000 // 256 + 1))
    text = ("[DeviceInfo]\nVendorName=V\nProductName=Huge\n" + heads + sections).encode()
    response = api.post("/api/profiles", files={"file": ("huge.eds", text)})
    assert response.status_code in (201, 413, 422), response.text
    if response.status_code != 201:
        assert response.json()["detail"]


def test_health_answers_while_a_large_zip_is_checked(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(app_settings, "user_profiles_dir", user_dir)
    members = [(f"n{n}-{name}", content) for n in range(3) for name, content, _ in CORPUS_FILES]
    archive = make_zip(members)
    with serve_app(create_app()) as url:
        result: dict[str, httpx.Response] = {}
        upload = threading.Thread(target=lambda: result.setdefault("r", httpx.post(
            f"{url}/api/profiles/batch", files={"files": ("all.zip", archive)}, timeout=120)))
        upload.start()
        answered = []
        while upload.is_alive():
            started = time.monotonic()
            health = httpx.get(f"{url}/api/health", timeout=10)
            answered.append((health.status_code, time.monotonic() - started))
        upload.join()
        assert result["r"].status_code == 200 and len(result["r"].json()["rows"]) == len(members)
        assert answered and all(code == 200 for code, _ in answered)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_uploads_never_give_a_server_error(api: TestClient, data: st.DataObject) -> None:
    """A mutation fuzz of valid files (EDS and XDD) through POST /api/profiles: 201 or a 4xx problem in words."""
    name, content = data.draw(st.sampled_from(
        [("servo.eds", BASE.encode())] + [(p.name, p.read_bytes()) for p in sorted(XDD_DIR.iterdir())]))
    mutated = bytearray(content)
    for _ in range(data.draw(st.integers(1, 8))):
        position = data.draw(st.integers(0, max(len(mutated) - 1, 0)))
        action = data.draw(st.sampled_from(["flip", "delete", "insert"]))
        if action == "flip" and mutated:
            mutated[position] = data.draw(st.integers(0, 255))
        elif action == "delete":
            del mutated[position:position + data.draw(st.integers(1, 60))]
        else:
            mutated[position:position] = data.draw(st.sampled_from(
                [b"\x00", b"[", b"]", b"=", b"\n", b"<", b">", b"&", b"$NODEID", b"0x", b";", b'"', b"\xff"]))
    response = api.post("/api/profiles", files={"file": (name, bytes(mutated))})
    assert response.status_code < 500, response.text
    if response.status_code >= 400:
        assert response.headers["content-type"].startswith("application/problem+json")
        assert response.json()["detail"]


def test_a_node_row_with_repaired_limits_asks_before_a_write(api: TestClient) -> None:
    name, content, _ = next(f for f in CORPUS_FILES if "signed-limits-on-unsigned32" in f[0])
    profile_id = api.post("/api/profiles", files={"file": (name, content)}).json()["id"]
    session = api.post("/api/sessions", json={"bus": f"virtual:{fresh_channel()}@500000", "name": "quirks"})
    assert session.status_code == 201, session.text
    session_id = session.json()["id"]
    assert api.post(f"/api/sessions/{session_id}/nodes", json={"node_id": 5, "profile_id": profile_id}
                    ).status_code == 201
    page = api.get(f"/sessions/{session_id}/nodes/5")
    assert page.status_code == 200
    rows = {m.group(1): m.group(0) for m in re.finditer(r'<tr id="p-[^"]*"[^>]*data-ref="([^"]+)".*?</tr>',
                                                          page.text, re.DOTALL)}
    repaired = html.unescape(rows["0x2000"])
    assert 'hx-confirm="0x2000: the limits of the device description were repaired or dropped on import' in repaired
    assert "limits dropped: LowLimit 0x80000000 &gt; HighLimit 0x7FFFFFFF" in rows["0x2000"]
    assert "badge warn tiny limits" in repaired
    assert "hx-confirm" not in rows["0x1017"] and "limits" not in rows["0x1017"]
    api.delete(f"/api/sessions/{session_id}")


def test_pdo_dcf_of_a_node_is_written_over_its_uploaded_file(user_dir: Path, monkeypatch: pytest.MonkeyPatch
                                                              ) -> None:
    """PDO tab 'Export DCF' of a node whose profile came from a vendor's file: the file's lines, comments, line
    ends and order stay; only ParameterValue and [DeviceComissioning] are added or changed."""
    monkeypatch.setattr(app_settings, "user_profiles_dir", user_dir)
    app = create_app(plant_file=REPO_ROOT / "plants" / "demo.json", plant_bus=f"virtual:{fresh_channel()}@500000",
                     latency="0ms")
    with TestClient(app) as client:
        generated = client.get("/api/profiles/siemens-micromaster4-canopen/eds").text
        vendor = ("; Vendor file as shipped (hand-edited copy)\n" + generated.replace(
            "ProfileId=siemens-micromaster4-canopen", "ProfileId=mm4-vendor-file")).replace("\n", "\r\n")
        assert client.post("/api/profiles", files={"file": ("mm4.eds", vendor.encode("cp1252"))}).status_code == 201
        nodes = "/api/sessions/demo-plant/nodes"
        assert client.delete(f"{nodes}/3").status_code == 204
        assert client.post(nodes, json={"node_id": 3, "profile_id": "mm4-vendor-file"}).status_code == 201
        dcf = client.get(f"{nodes}/3/pdos/dcf")
        assert dcf.status_code == 200, dcf.text
    written = dcf.text
    assert written.startswith("; Vendor file as shipped (hand-edited copy)\r\n")
    assert "\n" not in written.replace("\r\n", "")
    old, new = vendor.split("\r\n"), written.split("\r\n")
    for tag, old_from, old_to, new_from, new_to in difflib.SequenceMatcher(None, old, new, autojunk=False
                                                                          ).get_opcodes():
        assert tag in ("equal", "insert"), (old[old_from:old_to], new[new_from:new_to])
        for line in new[new_from:new_to] if tag == "insert" else []:
            assert re.match(r"(ParameterValue|NodeID)=|\[DeviceComissioning\]$|$", line), line
    assert written.count("ParameterValue=") > 10 and "NodeID=3" in written
