"""Line numbers of JSON values and duplicate keys (for profile files that are valid JSON but no valid profile)."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivebench.device.formats.json_lines import DuplicateKey, line_of, reject_duplicate_keys, value_lines

TEXT = """{
  "id": "x",
  "objects": [
    {"index": 4096},
    {
      "index": "0x1018",
      "name": "Identit\\u00e4t"
    }
  ],
  "empty": {},
  "n": [1.5e3, -2, true, null]
}"""


def test_lines_of_keys_and_array_items() -> None:
    data, lines = value_lines(TEXT)
    assert data == json.loads(TEXT)
    assert lines[()] == 1 and lines[("id",)] == 2 and lines[("objects",)] == 3
    assert lines[("objects", 0)] == 4 and lines[("objects", 1)] == 5 and lines[("objects", 1, "name")] == 7
    assert lines[("n", 3)] == 11


def test_line_of_a_deeper_path_is_its_parents() -> None:
    _, lines = value_lines(TEXT)
    assert line_of(lines, ("objects", 1, "index", "int_parsing")) == 6
    assert line_of(lines, ("nothing", "here")) == 1


def test_duplicate_key_is_named_with_both_lines() -> None:
    text = TEXT.replace('"name": "Identit\\u00e4t"', '"name": "a",\n      "name": "b"')
    with pytest.raises(DuplicateKey) as caught:
        reject_duplicate_keys(text.encode())
    assert (caught.value.key, caught.value.line, caught.value.first_line) == ("name", 8, 7)
    assert str(caught.value) == "duplicate key 'name' (first at line 7)"


def test_the_json_modules_extra_literals() -> None:
    data, lines = value_lines('{\n "a": NaN,\n "b": [Infinity, -Infinity]\n}')
    assert math.isnan(data["a"]) and data["b"] == [math.inf, -math.inf] and lines[("b", 1)] == 3
    with pytest.raises(DuplicateKey):
        reject_duplicate_keys('{"a": NaN, "a": 1}')


def test_the_same_key_in_two_objects_is_no_duplicate() -> None:
    reject_duplicate_keys('[{"a": 1}, {"a": 2}]')
    reject_duplicate_keys('{"a": 1')  # syntax errors are left to the validator, which names their line


_JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
                     | st.text(), lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner,
                                                                                             max_size=4), max_leaves=20)


@given(_JSON, st.sampled_from([None, 2]))
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_parses_like_the_json_module(value: object, indent: int | None) -> None:
    text = json.dumps(value, indent=indent)
    assert value_lines(text)[0] == json.loads(text)
