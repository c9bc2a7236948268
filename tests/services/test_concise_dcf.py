"""Concise DCF (CiA 302-3, 0x1F22): DriveBench's encoder and decoder against hand-written vectors laid out as the
standard prints the format, and against a reader of the standard's layout that shares no code with them."""

from __future__ import annotations

import pytest

from drivebench.device.formats.concise_dcf import ConciseEntry, decode, encode
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import InvalidValue
from drivebench.services.sets.concise_sets import generate, preview
from tests.concise_dcf_reader import read_concise_dcf

# Two entries: 0x1017 sub 0 (UNSIGNED16 producer heartbeat time) = 1000 ms, 0x6060 sub 0 (INTEGER8) = -1.
VECTOR = bytes.fromhex(
    "02000000"                   # number of entries: 2
    "1710" "00" "02000000" "e803"  # index 0x1017, sub 0, 2 bytes, 1000
    "6060" "00" "01000000" "ff"    # index 0x6060, sub 0, 1 byte, -1
)
ENTRIES = [ConciseEntry(0x1017, 0, b"\xe8\x03"), ConciseEntry(0x6060, 0, b"\xff")]


def test_encode_matches_the_standards_layout() -> None:
    assert encode(ENTRIES) == VECTOR
    assert read_concise_dcf(encode(ENTRIES)) == [(0x1017, 0, b"\xe8\x03"), (0x6060, 0, b"\xff")]


def test_decode_reads_the_vector_and_round_trips() -> None:
    assert decode(VECTOR) == ENTRIES
    assert encode(decode(VECTOR)) == VECTOR
    assert decode(b"\x00\x00\x00\x00") == []


@pytest.mark.parametrize(("data", "words"), [
    (b"\x01\x00", "entry count alone takes 4"),
    (VECTOR[:6], "inside the header of entry 1 of 2"),
    (VECTOR[:15], "inside the header of entry 2 of 2"),
    (VECTOR[:12], "announces 2 bytes; only 1 follow"),
    (VECTOR + b"\x00", "1 bytes after its 2 entries"),
])
def test_a_broken_concise_dcf_is_refused_in_words(data: bytes, words: str) -> None:
    with pytest.raises(InvalidValue, match=words):
        decode(data)


def test_generated_from_a_parameter_set_each_value_in_its_type() -> None:
    """A set of the generic servo: each entry is the object's address and the value in the object's width,
    little endian, as the independent reader sees it; the preview names each entry."""
    profile = ProfileRegistry().get("generic-cia402-servo")
    values = {"0x1017": 750, "0x1800.3": 200, "0x605A": -3, "0x6060": 1}
    data = generate(profile, values)
    read = {(index, sub): payload for index, sub, payload in read_concise_dcf(data)}
    assert read == {(0x1017, 0): (750).to_bytes(2, "little"), (0x1800, 3): (200).to_bytes(2, "little"),
                    (0x605A, 0): (-3).to_bytes(2, "little", signed=True), (0x6060, 0): b"\x01"}
    shown = preview(profile, 7, data)
    assert shown.count == 4 and shown.size == len(data)
    names = {(line.index, line.subindex): (line.name, line.value) for line in shown.lines}
    assert names[(0x1017, 0)][0] == "Producer heartbeat time"
    assert "750" in names[(0x1017, 0)][1]
    assert names[(0x605A, 0)][0] == "Quick stop option code"
