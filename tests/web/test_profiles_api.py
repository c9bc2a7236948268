"""The profiles REST API through the real app: list, schema, search, downloads, upload checks, delete.

Uploads go to a temporary ``user_profiles_dir`` (``settings`` is patched before the app builds its registry), so
no test leaves a file in the repository.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.device.profiles.profile import Profile
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, wait_until

EDS_DIR = REPO_ROOT / "tests" / "data" / "eds"
SERVO_EDS = EDS_DIR / "cia402_servo.eds"
MOTEC = "lenze-8400-motec-canopen"
SHIPPED = sorted(p.stem for p in (REPO_ROOT / "device_profiles").glob("*.json"))


def ids(api: TestClient) -> list[str]:
    return [p["id"] for p in api.get("/api/profiles").json()]


def upload(api: TestClient, name: str, content: bytes) -> Any:
    return api.post("/api/profiles", files={"file": (name, content)})


def broken_servo_eds(line_no: int) -> bytes:
    """The servo EDS cut before its object sections, with binary junk at line ``line_no`` (< 52): a file without
    object dictionary, what the import refuses (quirks of a file with one are read with warnings)."""
    lines = SERVO_EDS.read_bytes().split(b"\n")[:51]
    lines[line_no - 1] = b"\x00\x01\x02PK\x03\x04"
    return b"\n".join(lines)


# --- a small JSON-schema check (draft 2020-12 keywords pydantic emits), so no extra package is needed ------------
def schema_errors(value: Any, schema: dict[str, Any], root: dict[str, Any], path: str = "$") -> list[str]:
    if "$ref" in schema:
        target = root
        for part in schema["$ref"].removeprefix("#/").split("/"):
            target = target[part]
        return schema_errors(value, target, root, path)
    if "anyOf" in schema and all(schema_errors(value, s, root, path) for s in schema["anyOf"]):
        return [f"{path}: matches none of anyOf"]
    if "oneOf" in schema and sum(not schema_errors(value, s, root, path) for s in schema["oneOf"]) != 1:
        return [f"{path}: does not match exactly one of oneOf"]
    if "const" in schema and value != schema["const"]:
        return [f"{path}: {value!r} != {schema['const']!r}"]
    if "enum" in schema and value not in schema["enum"]:
        return [f"{path}: {value!r} not in {schema['enum']}"]
    kinds = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}
    kind = schema.get("type")
    if kind == "integer" and (not isinstance(value, int) or isinstance(value, bool)):
        return [f"{path}: {value!r} is not an integer"]
    if kind == "number" and (not isinstance(value, int | float) or isinstance(value, bool)):
        return [f"{path}: {value!r} is not a number"]
    if kind in kinds and not isinstance(value, kinds[kind]):
        return [f"{path}: {value!r} is not of type {kind}"]
    errors: list[str] = []
    if isinstance(value, str) and "pattern" in schema and not re.search(schema["pattern"], value):
        errors.append(f"{path}: {value!r} does not match {schema['pattern']}")
    if isinstance(value, int | float) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            errors.append(f"{path}: {value} < {schema['minimum']}")
        if "maximum" in schema and value > schema["maximum"]:
            errors.append(f"{path}: {value} > {schema['maximum']}")
    if isinstance(value, dict):
        properties = schema.get("properties", {})
        errors += [f"{path}: '{key}' is required" for key in schema.get("required", []) if key not in value]
        for key, item in value.items():
            if key in properties:
                errors += schema_errors(item, properties[key], root, f"{path}.{key}")
            elif schema.get("additionalProperties") is False:
                errors.append(f"{path}: '{key}' is not allowed")
            elif isinstance(schema.get("additionalProperties"), dict):
                errors += schema_errors(item, schema["additionalProperties"], root, f"{path}.{key}")
    if isinstance(value, list):
        if len(value) < schema.get("minItems", 0) or len(value) > schema.get("maxItems", len(value)):
            errors.append(f"{path}: {len(value)} items")
        prefix = schema.get("prefixItems", [])
        for position, item in enumerate(value):
            item_schema = prefix[position] if position < len(prefix) else schema.get("items")
            if isinstance(item_schema, dict):
                errors += schema_errors(item, item_schema, root, f"{path}[{position}]")
    return errors


# --- reading -------------------------------------------------------------------------------------------------
def test_list_names_every_shipped_profile_with_its_counts(api: TestClient) -> None:
    listed = {p["id"]: p for p in api.get("/api/profiles").json()}
    assert set(SHIPPED) <= set(listed)
    motec = json.loads((REPO_ROOT / "device_profiles" / f"{MOTEC}.json").read_text())
    row = listed[MOTEC]
    assert row["builtin"] is True
    assert row["vendor"] == "Lenze" and row["vendor_id"] == 0x3B
    assert row["family"] == "lenze-8400" and row["transport"] == "canopen"
    assert (row["objects"], row["parameters"]) == (len(motec["objects"]), len(motec["parameters"]))
    assert listed["lenze-8400-motec-ethercat"]["transport"] == "ethercat_coe"
    assert api.get("/api/profiles/load-errors").json() == []


def test_schema_is_a_json_schema_that_accepts_a_shipped_profile_and_rejects_a_broken_one(api: TestClient) -> None:
    schema = api.get("/api/profiles/schema").json()
    assert schema["type"] == "object" and "identity" in schema["required"]
    # the behaviour sections
    assert {"commands", "sdo_channels", "pdo_rules", "abort_texts", "switches"} <= set(schema["properties"])
    for profile_id in SHIPPED:
        shipped = json.loads((REPO_ROOT / "device_profiles" / f"{profile_id}.json").read_text())
        assert schema_errors(shipped, schema, schema) == [], profile_id
    broken = json.loads((REPO_ROOT / "device_profiles" / f"{MOTEC}.json").read_text())
    broken["objects"][0]["index"] = "index one"
    del broken["identity"]["vendor_name"]
    broken["surprise"] = 1
    problems = schema_errors(broken, schema, schema)
    assert any("objects[0].index" in p for p in problems)
    assert any("vendor_name" in p for p in problems)
    assert any("surprise" in p for p in problems)


def test_get_profile_and_unknown_profile(api: TestClient) -> None:
    profile = Profile.model_validate(api.get(f"/api/profiles/{MOTEC}").json())
    assert profile.identity.vendor_id == 0x3B
    missing = api.get("/api/profiles/no-such-drive")
    assert missing.status_code == 404
    assert missing.headers["content-type"].startswith("application/problem+json")
    assert "no-such-drive" in missing.json()["detail"]


@pytest.mark.parametrize("query", ["C00088", "c88", "88", "0x5FA7", "0x5fa7.0", "rated motor current"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_search_finds_rated_motor_current_first(api: TestClient, query: str) -> None:
    page = api.get(f"/api/profiles/{MOTEC}/parameters", params={"q": query}).json()
    first = page["items"][0]
    assert (first["ref"], first["name"], first["unit"]) == ("C00088", "Rated motor current", "A")
    assert (first["index"], first["subindex"], first["factor"], first["default"]) == ("0x5FA7", 0, 100, 10.2)


def test_search_pages_and_kinds(api: TestClient) -> None:
    everything = api.get(f"/api/profiles/{MOTEC}/parameters", params={"limit": 500}).json()
    total = everything["total"]
    assert total == len(everything["items"]) > 100
    refs = [row["ref"] for row in everything["items"]]
    pages = [api.get(f"/api/profiles/{MOTEC}/parameters", params={"offset": offset, "limit": 40}).json()
             for offset in range(0, total, 40)]
    assert [row["ref"] for page in pages for row in page["items"]] == refs
    assert all(page["total"] == total for page in pages)
    objects = api.get(f"/api/profiles/{MOTEC}/parameters", params={"kind": "objects", "q": "0x1018"}).json()
    assert objects["items"] and all(row["kind"] == "object" for row in objects["items"])
    assert objects["items"][0]["index"] == "0x1018"
    assert api.get(f"/api/profiles/{MOTEC}/parameters", params={"limit": 501}).status_code == 422
    assert api.get(f"/api/profiles/{MOTEC}/parameters", params={"q": "no such thing"}).json()["total"] == 0


def test_downloads_are_attachments_that_load_again(api: TestClient) -> None:
    as_json = api.get(f"/api/profiles/{MOTEC}/json")
    assert as_json.status_code == 200
    assert as_json.headers["content-disposition"] == f'attachment; filename="{MOTEC}.json"'
    original = Profile.model_validate(api.get(f"/api/profiles/{MOTEC}").json())
    assert Profile.model_validate_json(as_json.content) == original
    as_eds = api.get(f"/api/profiles/{MOTEC}/eds")
    assert as_eds.headers["content-disposition"] == f'attachment; filename="{MOTEC}.eds"'
    assert "[DeviceInfo]" in as_eds.text


def test_files_that_do_not_load_are_reported_with_line_and_the_rest_loads(user_dir: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    user_dir.mkdir()
    (user_dir / "bad.eds").write_bytes(broken_servo_eds(41))
    (user_dir / "good.eds").write_bytes(SERVO_EDS.read_bytes())
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as client:
        # stored uploads load in the background and lists do not wait for them (issue 33): the health says when
        assert wait_until(lambda: client.get("/api/health").json()["profiles"]["state"] == "loaded", 30)
        assert client.get("/api/profiles/load-errors").json() == [
            {"file": "bad.eds", "line": 41,
             "reason": "binary junk (control characters) instead of EDS text, and no object section"}]
        assert "good" in ids(client) and MOTEC in ids(client)


# --- upload ----------------------------------------------------------------------------------------------------
def test_upload_good_eds_is_listed_as_uploaded_and_stored_in_the_user_dir(api: TestClient, user_dir: Path) -> None:
    response = upload(api, SERVO_EDS.name, SERVO_EDS.read_bytes())
    assert response.status_code == 201, response.text
    created = response.json()
    assert created["builtin"] is False and created["product"] == "EM-Servo 400" and created["objects"] > 20
    assert created["id"] in ids(api)
    assert [p.name for p in user_dir.iterdir()] == [f"{created['id']}.eds"]
    found = api.get(f"/api/profiles/{created['id']}/parameters", params={"q": "0x6040"}).json()
    assert found["items"][0]["name"] == "Controlword"


def test_bad_eds_is_refused_with_its_line_and_nothing_is_lost(api: TestClient, user_dir: Path) -> None:
    kept = upload(api, SERVO_EDS.name, SERVO_EDS.read_bytes()).json()["id"]
    before = ids(api)
    stored = sorted(user_dir.iterdir())
    response = upload(api, "broken.eds", broken_servo_eds(41))
    assert response.status_code == 422
    assert response.headers["content-type"].startswith("application/problem+json")
    problem = response.json()
    assert (problem["source"], problem["line"]) == ("broken.eds", 41)
    assert "broken.eds:41:" in problem["detail"] and "binary junk" in problem["detail"]
    assert ids(api) == before and kept in before
    assert sorted(user_dir.iterdir()) == stored


@pytest.mark.parametrize(("name", "content", "line"), [
    ("latin.json", b'{\n  "id": "x",\n  "family": "caf\xe9"\n}', 3),
    ("junk.eds", b"[FileInfo]\nFileName=junk.eds\n\x00\x01\x02\xff binary\n", 3),
    ("junk.json", b'{\n  "id": "x",\n  oops\n}', 3),
])
def test_non_utf8_and_junk_are_refused_with_the_line(api: TestClient, name: str, content: bytes, line: int) -> None:
    response = upload(api, name, content)
    assert response.status_code == 422
    assert (response.json()["source"], response.json()["line"]) == (name, line)


def test_oversized_upload_is_refused_with_413(api: TestClient, user_dir: Path) -> None:
    api.app.state.drivebench.registry.max_upload_bytes = 4096  # type: ignore[attr-defined]
    content = SERVO_EDS.read_bytes()
    assert len(content) > 4096
    declared = upload(api, SERVO_EDS.name, content)
    assert declared.status_code == 413
    assert declared.json()["title"] == "Upload too large" and "4 KiB" in declared.json()["detail"]
    # Without a Content-Length (chunked) the stream is cut at the limit as it arrives.
    boundary = "drivebench-test"
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"big.eds\"\r\n\r\n".encode()
            + content * 30 + f"\r\n--{boundary}--\r\n".encode())
    chunked = api.post("/api/profiles", content=iter([body[i:i + 8192] for i in range(0, len(body), 8192)]),
                       headers={"Content-Type": f"multipart/form-data; boundary={boundary}"})
    assert chunked.status_code == 413
    assert not user_dir.exists() or list(user_dir.iterdir()) == []


def test_path_traversal_in_the_file_name_stays_in_the_user_dir(api: TestClient, tmp_path: Path, user_dir: Path
                                                                ) -> None:
    response = upload(api, "../../x.eds", SERVO_EDS.read_bytes())
    assert response.status_code == 201
    assert [p.name for p in user_dir.iterdir()] == [f"{response.json()['id']}.eds"]
    assert not (tmp_path / "x.eds").exists() and not (user_dir.parent.parent / "x.eds").exists()
    refused = upload(api, "..\\..\\evil.eds", broken_servo_eds(20))
    assert refused.json()["source"] == "evil.eds"


def test_upload_without_a_file_is_a_problem(api: TestClient) -> None:
    response = api.post("/api/profiles", data={"note": "no file"}, files={"other": ("a.txt", b"x")})
    assert response.status_code == 422
    assert "no file" in response.json()["detail"]


# --- delete ----------------------------------------------------------------------------------------------------
def test_delete_uploaded_profile_and_refuse_built_in(api: TestClient, user_dir: Path) -> None:
    uploaded = upload(api, SERVO_EDS.name, SERVO_EDS.read_bytes()).json()["id"]
    built_in = api.delete(f"/api/profiles/{MOTEC}")
    assert built_in.status_code == 409
    assert built_in.headers["content-type"].startswith("application/problem+json")
    assert MOTEC in ids(api)
    assert api.delete(f"/api/profiles/{uploaded}").status_code == 204
    assert uploaded not in ids(api)
    assert list(user_dir.iterdir()) == []
    assert api.delete(f"/api/profiles/{uploaded}").status_code == 404


def test_delete_refuses_a_profile_a_node_uses(api: TestClient) -> None:
    uploaded = upload(api, SERVO_EDS.name, SERVO_EDS.read_bytes()).json()["id"]
    session = api.post("/api/sessions", json={"bus": f"virtual:{fresh_channel()}@500000", "name": "Bench"}).json()
    assert api.post(f"/api/sessions/{session['id']}/nodes", json={"node_id": 7, "profile_id": uploaded}
                    ).status_code == 201
    refused = api.delete(f"/api/profiles/{uploaded}")
    assert refused.status_code == 409
    assert "node 7 of 'Bench'" in refused.json()["detail"]
    assert uploaded in ids(api)


def test_json_that_is_no_valid_profile_is_refused_with_its_line_and_nothing_is_lost(api: TestClient,
                                                                                    user_dir: Path) -> None:
    data = api.get(f"/api/profiles/{MOTEC}").json() | {"id": "my-motec"}
    assert upload(api, "mine.json", json.dumps(data, indent=2).encode()).status_code == 201
    before, stored = ids(api), sorted(user_dir.iterdir())
    data["objects"].append(dict(data["objects"][0]))
    text = json.dumps(data, indent=2)
    response = upload(api, "mine.json", text.encode())
    assert response.status_code == 422
    problem = response.json()
    assert problem["source"] == "mine.json" and text.splitlines()[problem["line"] - 1] == "    {"
    assert f"mine.json:{problem['line']}: objects.{len(data['objects']) - 1}: duplicate object 0x" in problem["detail"]
    assert ids(api) == before and sorted(user_dir.iterdir()) == stored
    assert api.get("/api/profiles/my-motec").json()["objects"] == data["objects"][:-1]
