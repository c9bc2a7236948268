"""Profile files that are valid JSON but no valid profile are refused with file name, line and reason."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import ProfileRegistry, load_profile_file
from drivebench.errors import ProfileError

MOTEC_FILE = REPO_ROOT / "device_profiles" / "lenze-8400-motec-canopen.json"


def motec(**changes: object) -> dict:
    data = json.loads(MOTEC_FILE.read_text(encoding="utf-8"))
    return data | {"id": "my-motec"} | changes


def line_with(text: str, needle: str, nth: int = 1) -> int:
    hits = [n for n, line in enumerate(text.splitlines(), start=1) if needle in line]
    return hits[nth - 1]


def item_line(text: str, field: str, position: int) -> int:
    """The line of the ``position``-th item of the top-level list ``field`` in ``json.dumps(..., indent=2)`` text."""
    lines = text.splitlines()
    start = lines.index(f'  "{field}": [')
    return [n for n, line in enumerate(lines, start=1) if n > start and line == "    {"][position]


def refused(text: str, name: str = "mine.json") -> ProfileError:
    with pytest.raises(ProfileError) as caught:
        load_profile_file(text.encode(), name)
    assert caught.value.source == name and str(caught.value).startswith(f"{name}:{caught.value.line}: ")
    return caught.value


def test_the_shipped_file_loads_under_another_id() -> None:
    assert load_profile_file(json.dumps(motec(), indent=2).encode(), "mine.json").id == "my-motec"


def test_duplicate_object_names_the_second_one() -> None:
    data = motec()
    data["objects"].append(dict(data["objects"][3]))
    text = json.dumps(data, indent=2)
    error = refused(text)
    second = len(data["objects"]) - 1
    assert error.line == item_line(text, "objects", second)
    assert f"mine.json:{error.line}: objects.{second}: duplicate object 0x" in str(error)


def test_duplicate_parameter_names_its_line() -> None:
    data = motec()
    data["parameters"].insert(5, dict(data["parameters"][0]))
    text = json.dumps(data, indent=2)
    error = refused(text)
    assert error.line == item_line(text, "parameters", 5)
    assert f": parameters.5: duplicate parameter {data['parameters'][0]['code']}" in str(error)


def test_wrong_data_type_names_its_line() -> None:
    data = motec()
    data["objects"][2]["data_type"] = "UNSIGNED99"
    text = json.dumps(data, indent=2)
    error = refused(text)
    assert error.line == line_with(text, '"UNSIGNED99"')
    assert ": objects.2.data_type: Input should be" in str(error)


def test_impossible_range_names_the_entry() -> None:
    data = motec()
    data["parameters"][7] |= {"min": 10, "max": 1}
    text = json.dumps(data, indent=2)
    error = refused(text)
    assert error.line == item_line(text, "parameters", 7)
    assert ": parameters.7: " in str(error) and "min 10 is greater than max 1" in str(error)


def test_duplicate_key_is_refused() -> None:
    text = json.dumps(motec(), indent=2).replace('"version": "1",', '"version": "1",\n  "version": "2",', 1)
    error = refused(text)
    assert error.line == line_with(text, '"version"', 2)
    assert f"duplicate key 'version' (first at line {error.line - 1})" in str(error)


def test_several_errors_say_how_many_more() -> None:
    data = motec()
    data["objects"][0]["data_type"] = "X"
    data["objects"][1]["data_type"] = "Y"
    assert str(refused(json.dumps(data, indent=2))).endswith("(and 1 more)")


def test_a_bad_upload_leaves_the_registry_as_it_was(tmp_path: Path) -> None:
    registry = ProfileRegistry(user_profiles_dir=tmp_path / "uploads")
    good = registry.add_upload("mine.json", json.dumps(motec(), indent=2).encode())
    before = [p.id for p in registry.all()]
    data = motec()
    data["objects"].append(dict(data["objects"][0]))
    with pytest.raises(ProfileError):
        registry.add_upload("mine.json", json.dumps(data, indent=2).encode())
    assert [p.id for p in registry.all()] == before and registry.get("my-motec") == good
    assert [p.name for p in (tmp_path / "uploads").iterdir()] == ["my-motec.json"]


@pytest.mark.parametrize(("name", "content", "message"), [
    ("motec.eds", json.dumps(motec()).encode(), "this is a JSON profile, not an EDS: name the file .json"),
    ("servo.json", (REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds").read_bytes(),
     "this is an EDS/DCF (INI text), not a JSON profile: name the file .eds or .dcf"),
    ("servo.txt", (REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds").read_bytes(),
     "unknown profile file type .txt; use .json, .eds, .dcf, .xdd or .xdc; this looks like an EDS, name it .eds"),
    ("motec", json.dumps(motec()).encode(),
     "unknown profile file type (none); use .json, .eds, .dcf, .xdd or .xdc; this looks like a JSON profile, "
     "name it .json"),
])
def test_a_file_with_the_wrong_suffix_is_named_for_what_it_is(name: str, content: bytes, message: str) -> None:
    with pytest.raises(ProfileError) as caught:
        load_profile_file(content, name)
    assert caught.value.source == name and message in str(caught.value)
