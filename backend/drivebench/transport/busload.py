"""Exact bit count of classic CAN frames on the wire, for bus-load figures (python-can has no helper for this).

A classic CAN frame is SOF, arbitration field, control field, data, CRC-15 (all bit-stuffed: after five equal
bits the transmitter inserts one complementary bit, which counts towards the next run), then CRC delimiter (1),
ACK slot and delimiter (2), EOF (7) and the intermission (3) that keeps the next frame apart.

Without stuffing a frame is 47 + 8·n bits (11-bit id) or 67 + 8·n bits (29-bit id); stuffing adds 0 to
⌊(34 + 8·n − 1) / 4⌋ (11-bit) or ⌊(54 + 8·n − 1) / 4⌋ (29-bit) bits depending on the bit pattern.

CAN FD frames are not classic frames: they are counted as if sent in classic format with their length rounded
to 8 data bytes at most, which is an estimate, not an exact count (the data phase runs at another bit rate).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from functools import lru_cache

import can

CRC15_POLY = 0x4599
TRAILER_BITS = 1 + 2 + 7 + 3
"""CRC delimiter, ACK slot + delimiter, end of frame, intermission (not stuffed)."""

CACHE_SIZE = 8192
"""Distinct (id, flags, dlc) frame heads whose CRC and stuffing state is remembered (LRU)."""


def crc15(bits: str) -> int:
    """CAN CRC-15 (polynomial 0x4599) over a string of '0'/'1' characters."""
    crc = 0
    for bit in bits:
        feedback = (bit == "1") ^ (crc >> 14)
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= CRC15_POLY
    return crc


def stuff_bit_count(bits: str) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` (SOF .. CRC sequence)."""
    stuffed = 0
    run = 0
    last = ""
    for bit in bits:
        if bit == last:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:
            stuffed += 1
            # The complementary stuff bit starts a new run of length 1.
            last = "0" if bit == "1" else "1"
            run = 1
    return stuffed


def _head_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int) -> str:
    """The bits from SOF to the end of the control field (DLC), before stuffing, as '0'/'1' characters."""
    rtr = "1" if is_remote else "0"
    if is_extended:
        base, extension = arbitration_id >> 18, arbitration_id & 0x3FFFF
        # SOF, base id, SRR (recessive), IDE (recessive), id extension, RTR, r1, r0.
        return f"0{base:011b}11{extension:018b}{rtr}00{dlc & 0xF:04b}"
    # SOF, id, RTR, IDE (dominant), r0.
    return f"0{arbitration_id:011b}{rtr}00{dlc & 0xF:04b}"


def stuffed_section(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> str:
    """The bits from SOF to the end of the CRC sequence, before stuffing, as '0'/'1' characters."""
    payload = "" if is_remote else "".join(f"{byte:08b}" for byte in data)
    bits = _head_bits(arbitration_id, is_extended, is_remote, dlc) + payload
    return f"{bits}{crc15(bits):015b}"


def _crc15_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ CRC15_POLY) if crc & 0x4000 else crc << 1
            crc &= 0x7FFF
        table.append(crc)
    return table


def _stuffing(bits: Iterable[int], last: int = 0, run: int = 0) -> tuple[int, int, int]:
    """Stuff bits a transmitter inserts into ``bits`` (0/1) when the bits before them ended in a run of ``run``
    bits equal to ``last`` (run 0: the frame starts with them): (stuff bits, last bit after, run after)."""
    stuffed = 0
    for bit in bits:
        if bit == last and run:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:
            stuffed += 1
            last, run = 1 - bit, 1
    return stuffed, last, run


def _stuff_table(width: int = 8) -> list[tuple[int, int, int]]:
    """For (last bit, run length 0..4, ``width``-bit chunk): (stuff bits inserted, last bit after, run after)."""
    shifts = range(width - 1, -1, -1)
    return [_stuffing(((chunk >> shift) & 1 for shift in shifts), last, run)
            for last in (0, 1) for run in range(5) for chunk in range(1 << width)]


def _stepper(table: list[tuple[int, int, int]]) -> list[tuple[int, int]]:
    """The stuff table with the state folded into the next index base: (stuff bits, (last * 5 + run) * 256)."""
    return [(added, (last * 5 + run) << 8) for added, last, run in table]


_CRC_TABLE: list[int] = []
_STUFF_STEP: list[tuple[int, int]] = []
_STUFF7_STEP: list[tuple[int, int]] = []
"""The byte tables of :func:`_fast_bits`, made by the first frame counted (:func:`_first_bits`)."""


@lru_cache(maxsize=CACHE_SIZE)
def _header_state(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int) -> tuple[int, int, int, int, int]:
    """CRC register, stuff bits so far, last bit, run length and bit count after SOF .. DLC (same for every frame
    of a COB-ID and length, so it is worked out bit by bit once)."""
    head = _head_bits(arbitration_id, is_extended, is_remote, dlc)
    stuffed, last, run = _stuffing(int(char) for char in head)
    return crc15(head), stuffed, last, run, len(head)


def _fast_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> int:
    """Same result as the string reference (``stuffed_section`` + ``stuff_bit_count``): the header state is
    cached per COB-ID and length, data bytes and the CRC go through byte tables (CRC and stuffing)."""
    crc, stuffed, last, run, length = _header_state(arbitration_id, is_extended, is_remote, dlc)
    crc_table, step = _CRC_TABLE, _STUFF_STEP
    base = (last * 5 + run) << 8
    for byte in data:
        crc = ((crc << 8) & 0x7FFF) ^ crc_table[((crc >> 7) ^ byte) & 0xFF]
        added, base = step[base + byte]
        stuffed += added
    # The 15 CRC bits: the top 7 (the 7-bit table has 128 entries per state), then the low 8.
    added, base = _STUFF7_STEP[(base >> 1) + (crc >> 8)]
    stuffed += added
    added, base = step[base + (crc & 0xFF)]
    return length + 8 * len(data) + 15 + stuffed + added + TRAILER_BITS


def reference_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> int:
    """Bit by bit, for reading and for checking the table-driven count."""
    bits = stuffed_section(arbitration_id, is_extended, is_remote, dlc, data)
    return len(bits) + stuff_bit_count(bits) + TRAILER_BITS


def _first_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> int:
    """The first frame counted makes the byte tables (not the module's import: ~3,800 stuffing runs, a few
    hundredths of a second of every server start, issue 33); every frame after it goes straight to
    :func:`_fast_bits`. Two threads that count their first frame at once make the same tables."""
    global _CRC_TABLE, _STUFF_STEP, _STUFF7_STEP, _bits_cached
    _CRC_TABLE, _STUFF_STEP, _STUFF7_STEP = _crc15_table(), _stepper(_stuff_table()), _stepper(_stuff_table(7))
    _bits_cached = _fast_bits
    return _fast_bits(arbitration_id, is_extended, is_remote, dlc, data)


_bits_cached = _first_bits


def frame_bits(arbitration_id: int, data: bytes = b"", *, is_extended: bool = False, is_remote: bool = False,
               dlc: int | None = None) -> int:
    """Exact bits one classic CAN frame occupies on the bus, intermission included.

    ``dlc`` defaults to ``len(data)``; for a remote frame it is the requested length (no data is sent).
    Data beyond 8 bytes (CAN FD) is cut to 8, see the module docstring.
    """
    payload = b"" if is_remote else bytes(data[:8])
    code = len(payload) if dlc is None else dlc
    return _bits_cached(arbitration_id, is_extended, is_remote, min(code, 15), payload)


def message_bits(msg: can.Message) -> int:
    """Exact bits of a python-can message (0 for error frames, which are reports, not frames on the wire)."""
    if msg.is_error_frame:
        return 0
    if msg.is_remote_frame:
        return _bits_cached(msg.arbitration_id, msg.is_extended_id, True, min(msg.dlc, 15), b"")
    payload = bytes(msg.data[:8])
    dlc = msg.dlc if not msg.is_fd and msg.dlc <= 15 else len(payload)
    return _bits_cached(msg.arbitration_id, msg.is_extended_id, False, dlc, payload)


def nominal_bits(data_length: int, *, is_extended: bool = False) -> int:
    """Bits of a frame without stuff bits (the lower bound)."""
    return (67 if is_extended else 47) + 8 * data_length


def worst_case_bits(data_length: int, *, is_extended: bool = False) -> int:
    """Bits of a frame with the most stuff bits any pattern can cause (the upper bound)."""
    stuffable = (54 if is_extended else 34) + 8 * data_length
    return nominal_bits(data_length, is_extended=is_extended) + (stuffable - 1) // 4


def load_percent(bits: int, seconds: float, bitrate: int) -> float:
    """Share of the bus's capacity ``bits`` used over ``seconds`` at ``bitrate`` bit/s, in percent."""
    if seconds <= 0 or bitrate <= 0:
        return 0.0
    return 100.0 * bits / (seconds * bitrate)


def cache_info() -> str:
    return str(_header_state.cache_info())


# --- load over time, by the frames' own timestamps ------------------------------------------------------------
REORDER_S = 0.1
"""A window closes once a frame this far past its end has been counted (frames from several sources, received and
sent, reach the counter a little out of order)."""
IDLE_CLOSE_S = 5.0
"""...or, on a bus without any frame, once the clock is this far past its end (a CANopen bus with heartbeats closes
its windows by their frames, a tenth of a second after their end). A process stalled for longer still adds the
frames it counts late to their closed window: the history comes right, but a snapshot or live chart taken during
the stall showed the window without them."""
PLAUSIBLE_S = 60.0
"""A timestamp this close to the wall clock is wall-clock time (socketcand, SocketCAN, virtual bus, frames sent by
the tool); further off it is an adapter's own clock, mapped with the smallest lag seen."""


class FrameClock:
    """Maps a frame's own timestamp to wall-clock seconds: the adapter's or hub's time when it has one (so a frame
    counted late, after a stall of the process, still lands in the second it was on the bus), the time of
    counting when it has none."""

    def __init__(self) -> None:
        self._offset: float | None = None
        """For an adapter clock that is not wall-clock time: wall clock minus adapter clock (smallest lag)."""

    def time_of(self, timestamp: float, wall_now: float) -> float:
        if not timestamp:
            return wall_now
        if abs(timestamp - wall_now) <= PLAUSIBLE_S:
            return timestamp
        lag = wall_now - timestamp
        offset = self._offset
        if offset is None or lag < offset or timestamp + offset < wall_now - PLAUSIBLE_S:  # first, faster, restarted
            offset = self._offset = lag
        return timestamp + offset


class LoadWindows:
    """Frames and exact bits per one-second window of frame time (``FrameClock``), closed in order: a window is
    closed when a frame ``REORDER_S`` past its end was counted or the clock is ``IDLE_CLOSE_S`` past it; the
    load figures (each point, the peak, frames per second) come from closed windows only. A frame that comes in
    after its window closed (a stall longer than ``IDLE_CLOSE_S``) is added to the closed window, not to the
    current one. Not thread-safe: the caller holds its lock."""

    def __init__(self, bitrate: int, history_s: int, start: float,
                 on_close: Callable[[float], None] | None = None) -> None:
        self.bitrate = bitrate
        self.history: deque[tuple[int, int, int]] = deque(maxlen=history_s)
        """Closed windows, oldest first: (second, frames, bits)."""
        self.peak: tuple[float, float] = (0.0, 0.0)
        """Highest load of a closed window (percent) and its second."""
        self._open: dict[int, list[int]] = {}
        self._closed_until = int(start)
        self._on_close = on_close
        """Called with the end of each window as it closes (before the frame that closed it is counted)."""

    def add(self, stamp: float, bits: int) -> None:
        second = int(stamp)
        if second < self._closed_until:
            self._amend(second, bits)
            return
        self.close_until(stamp - REORDER_S)
        window = self._open.get(second)
        if window is None:
            window = self._open[second] = [0, 0]
        window[0] += 1
        window[1] += bits

    def close_idle(self, wall_now: float) -> None:
        self.close_until(wall_now - IDLE_CLOSE_S)

    def close_until(self, moment: float) -> None:
        """Close every window that ends at or before ``moment``."""
        until = int(moment)
        if until <= self._closed_until:
            return
        history_s = self.history.maxlen or 1
        first = max(self._closed_until, until - history_s)
        for second in [s for s in self._open if s < first]:  # older than the history keeps
            del self._open[second]
        for second in range(first, until):
            frames, bits = self._open.pop(second, (0, 0))
            self._push(second, frames, bits)
            if self._on_close is not None:
                self._on_close(second + 1.0)
        self._closed_until = until

    def _push(self, second: int, frames: int, bits: int) -> None:
        self.history.append((second, frames, bits))
        load = self.percent(bits)
        if load > self.peak[0]:
            self.peak = (load, float(second))

    def _amend(self, second: int, bits: int) -> None:
        history = self.history
        if not history or second < history[0][0]:
            return
        index = second - history[0][0]
        if index >= len(history) or history[index][0] != second:
            return
        _, frames, old_bits = history[index]
        history[index] = (second, frames + 1, old_bits + bits)
        load = self.percent(old_bits + bits)
        if load > self.peak[0]:
            self.peak = (load, float(second))

    def percent(self, bits: int) -> float:
        return 100.0 * bits / self.bitrate

    def last(self) -> tuple[int, int, int] | None:
        return self.history[-1] if self.history else None

    def frames_per_s(self, window_s: int) -> float:
        """Frames per second over the last ``window_s`` closed windows (fewer while fewer have closed)."""
        count = min(window_s, len(self.history))
        return sum(self.history[-i][1] for i in range(1, count + 1)) / count if count else 0.0
