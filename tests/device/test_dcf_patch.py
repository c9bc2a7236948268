"""A DCF written over the original file keeps every section, key, comment and their order; only values change."""

from __future__ import annotations

import difflib
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivebench.device.formats.eds import decode_text, read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles.profile import Profile
from tests.device.quirk_corpus import CORPUS_FILES

NEW_SECTIONS = re.compile(r"^\[(DeviceComissioning|[0-9A-F]{4}Value)\]$", re.IGNORECASE)
CHANGED_KEYS = re.compile(r"^\s*(ParameterValue|NrOfEntries|NodeID|Baudrate|\d+)\s*=", re.IGNORECASE)


def original_lines_kept(original: str, written: str) -> None:
    """Every line of the original is in the DCF, in order; a line that differs or is new sets a value."""
    old = re.split(r"\r\n|\r|\n", original)
    new = re.split(r"\r\n|\r|\n", written)
    for tag, old_from, old_to, new_from, new_to in difflib.SequenceMatcher(None, old, new, autojunk=False
                                                                          ).get_opcodes():
        if tag == "equal":
            continue
        assert tag in ("replace", "insert"), f"lines {old[old_from:old_to]} of the original were lost"
        replaced = old[old_from:old_to]
        assert all(CHANGED_KEYS.match(line) for line in replaced), f"lines {replaced} were changed"
        keys = {line.split("=", 1)[0].strip().lower() for line in replaced}
        for line in new[new_from:new_to]:
            assert (CHANGED_KEYS.match(line) or not line.strip() or NEW_SECTIONS.match(line)), f"new line {line!r}"
            if CHANGED_KEYS.match(line) and tag == "replace" and len(replaced) == new_to - new_from:
                assert line.split("=", 1)[0].strip().lower() in keys


def writable(profile: Profile) -> list[tuple[int, int]]:
    return [(o.index, o.subindex) for o in profile.objects
            if o.access.writable and o.data_type.is_integer and o.data_type.raw_limits()]


@pytest.mark.parametrize(("name", "content", "case"), CORPUS_FILES, ids=[c[0] for c in CORPUS_FILES])
def test_dcf_over_a_corpus_file_changes_only_values(name: str, content: bytes, case: object) -> None:
    profile = read_eds(content, source=name).profile
    values = {address: 1 for address in writable(profile)[:4]}
    written = export_eds(profile, node_id=7, baud_kbit=250, values=values, dcf=True, original=content)
    original_lines_kept(decode_text(content, name), written)
    again = read_eds(written, source=name).profile
    for address in values:
        assert next(o for o in again.objects if (o.index, o.subindex) == address).parameter_value == 1
    assert again.extra_sections["DeviceComissioning"]["NodeID"] == "7"
    assert again.extra_sections["DeviceComissioning"]["Baudrate"] == "250"
    unchanged = [o for o in again.objects if (o.index, o.subindex) not in values]
    assert unchanged == [o for o in profile.objects if (o.index, o.subindex) not in values]


def test_compact_array_values_go_to_the_value_section_and_line_ends_stay() -> None:
    name, content, _ = next(f for f in CORPUS_FILES if "compact-sub-obj-with-names-values" in f[0])
    crlf = content.replace(b"\n", b"\r\n")
    profile = read_eds(crlf, source=name).profile
    written = export_eds(profile, node_id=3, values={(0x2008, 3): -7, (0x2008, 2): 4}, dcf=True, original=crlf)
    assert "[2008Value]\r\nNrOfEntries=2\r\n2=4\r\n3=-7\r\n" in written
    assert "\n" not in written.replace("\r\n", "")
    again = read_eds(written, source=name).profile
    assert [o.parameter_value for o in again.objects if o.index == 0x2008] == [None, None, 4, -7]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(CORPUS_FILES), st.data())
def test_any_values_over_any_corpus_file(corpus_file: tuple[str, bytes, object], data: st.DataObject) -> None:
    name, content, _ = corpus_file
    profile = read_eds(content, source=name).profile
    by_address = {(o.index, o.subindex): o for o in profile.objects}
    chosen = data.draw(st.lists(st.sampled_from(writable(profile)), unique=True, max_size=6))
    values: dict[tuple[int, int], int | float | str] = {}
    for address in chosen:
        low, high = by_address[address].data_type.raw_limits() or (0, 0)
        values[address] = data.draw(st.integers(low, high))
    node = data.draw(st.integers(1, 127))
    written = export_eds(profile, node_id=node, values=values, dcf=True, original=content)
    original_lines_kept(decode_text(content, name), written)
    again = {(o.index, o.subindex): o for o in read_eds(written, source=name).profile.objects}
    assert {a: again[a].parameter_value for a in values} == values
