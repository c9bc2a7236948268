"""Exact CAN frame bit counts (stuff bits included) and bus load, against hand-computed values."""

from __future__ import annotations

from collections import deque

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivebench.transport.busload import (
    FrameClock,
    LoadWindows,
    crc15,
    frame_bits,
    load_percent,
    message_bits,
    nominal_bits,
    reference_bits,
    stuff_bit_count,
    stuffed_section,
    worst_case_bits,
)


@pytest.mark.parametrize(("bits", "stuffed"), [
    ("0101010101", 0),          # best case: no run reaches five
    ("00000", 1),               # one run of five
    ("0000", 0),
    ("1111100000", 2),          # the stuffed 0 starts the next run: 0 + 0000 is five again
    ("0000011110000", 3),       # worst case: 5, then every 4 (stuff bit + 4 originals)
    ("00000" + "1111" + "0000" + "1111", 4),
])
def test_stuff_bits_hand_counted(bits: str, stuffed: int) -> None:
    assert stuff_bit_count(bits) == stuffed


def test_all_zero_frame_hand_computed() -> None:
    """Id 0x000, DLC 0: SOF, 11 id bits, RTR, IDE, r0, DLC are 19 dominant bits and the CRC of zeros is 0, so
    34 zeros are stuffed: one stuff bit after every 5 of them, 6 in all. 34 + 6 + 13 (CRC delimiter, ACK slot
    and delimiter, EOF, intermission) = 53."""
    assert crc15("0" * 19) == 0
    assert stuffed_section(0x000, False, False, 0, b"") == "0" * 34
    assert frame_bits(0x000) == 53
    assert reference_bits(0x000, False, False, 0, b"") == 53


def test_bounds_match_the_published_figures() -> None:
    """Davis, Burns et al. (2007): 8 data bytes take at most 135 bits (11-bit id) and 160 bits (29-bit id),
    intermission included; without stuffing 111 and 131."""
    assert worst_case_bits(8) == 135 and nominal_bits(8) == 111
    assert worst_case_bits(8, is_extended=True) == 160 and nominal_bits(8, is_extended=True) == 131
    assert worst_case_bits(0) == 47 + 8 and nominal_bits(0) == 47


@given(st.integers(0, 0x7FF), st.binary(max_size=8), st.booleans())
def test_table_driven_count_equals_bit_by_bit_standard(cob_id: int, data: bytes, remote: bool) -> None:
    payload = b"" if remote else data
    bits = frame_bits(cob_id, payload, is_remote=remote, dlc=len(data))
    assert bits == reference_bits(cob_id, False, remote, len(data), payload)
    assert nominal_bits(len(payload)) <= bits <= worst_case_bits(len(payload))


@given(st.integers(0, 0x1FFFFFFF), st.binary(max_size=8))
def test_table_driven_count_equals_bit_by_bit_extended(cob_id: int, data: bytes) -> None:
    bits = frame_bits(cob_id, data, is_extended=True)
    assert bits == reference_bits(cob_id, True, False, len(data), data)
    assert nominal_bits(len(data), is_extended=True) <= bits <= worst_case_bits(len(data), is_extended=True)


def test_message_bits() -> None:
    assert message_bits(can.Message(arbitration_id=0x000, data=b"", is_extended_id=False)) == 53
    assert message_bits(can.Message(is_error_frame=True, arbitration_id=0x80, data=bytes(8))) == 0
    remote = can.Message(arbitration_id=0x705, is_remote_frame=True, dlc=1, is_extended_id=False)
    assert message_bits(remote) == reference_bits(0x705, False, True, 1, b"")


def test_load_of_a_known_frame_list() -> None:
    """1000 all-zero frames (53 bits each) in one second at 500 kbit/s: 53,000 / 500,000 = 10.6 %; two SYNC-sized
    worst cases per ms at 125 kbit/s: 2 * 55 * 1000 bits / 125,000 = 88 %."""
    bits = sum(frame_bits(0x000) for _ in range(1000))
    assert bits == 53_000
    assert load_percent(bits, 1.0, 500_000) == pytest.approx(10.6)
    assert load_percent(2 * worst_case_bits(0) * 1000, 1.0, 125_000) == pytest.approx(88.0)
    assert load_percent(1000, 0.0, 500_000) == 0.0


def test_load_windows_close_in_frame_time_and_take_late_frames_into_their_own_second() -> None:
    closed: list[float] = []
    windows = LoadWindows(1000, history_s=10, start=100.0, on_close=closed.append)
    for stamp in (100.2, 100.5, 101.05):  # 101.05: within the reorder tolerance, 100 stays open
        windows.add(stamp, 100)
    assert windows.history == deque() and closed == []
    windows.add(100.9, 100)  # out of order, still in time
    windows.add(101.2, 100)
    assert list(windows.history) == [(100, 3, 300)] and closed == [101.0]
    windows.close_idle(108.5)  # a bus without frames: closed by the clock, IDLE_CLOSE_S (5 s) after their end
    assert [second for second, _, _ in windows.history] == [100, 101, 102]
    windows.add(101.5, 50)  # counted after a stall: into its own (closed) second, not the current one
    assert windows.history[1] == (101, 3, 250) and windows.peak == (30.0, 100.0)
    assert windows.frames_per_s(2) == (3 + 0) / 2 and windows.frames_per_s(5) == (3 + 3 + 0) / 3

    clock = FrameClock()
    assert clock.time_of(0.0, 1_000_000.0) == 1_000_000.0  # no timestamp: the time of counting
    assert clock.time_of(999_999.5, 1_000_000.0) == 999_999.5  # wall-clock time: as it is
    assert clock.time_of(20.0, 1_000_000.3) == pytest.approx(1_000_000.3)  # an adapter's own clock: mapped
    assert clock.time_of(21.0, 1_000_001.5) == pytest.approx(1_000_001.3)  # counted 0.2 s late: still its time
