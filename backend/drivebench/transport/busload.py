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

from functools import lru_cache

import can

CRC15_POLY = 0x4599
TRAILER_BITS = 1 + 2 + 7 + 3
"""CRC delimiter, ACK slot + delimiter, end of frame, intermission (not stuffed)."""

CACHE_SIZE = 8192
"""Distinct (id, flags, dlc, data) frames whose bit count is remembered (LRU)."""


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


def stuffed_section(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> str:
    """The bits from SOF to the end of the CRC sequence, before stuffing, as '0'/'1' characters."""
    rtr = "1" if is_remote else "0"
    if is_extended:
        base, extension = arbitration_id >> 18, arbitration_id & 0x3FFFF
        # SOF, base id, SRR (recessive), IDE (recessive), id extension, RTR, r1, r0.
        head = f"0{base:011b}11{extension:018b}{rtr}00"
    else:
        # SOF, id, RTR, IDE (dominant), r0.
        head = f"0{arbitration_id:011b}{rtr}00"
    payload = "" if is_remote else "".join(f"{byte:08b}" for byte in data)
    bits = f"{head}{dlc & 0xF:04b}{payload}"
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


def _stuff_table() -> list[tuple[int, int, int]]:
    """For (last bit, run length 0..4, byte): (stuff bits inserted, last bit after, run length after)."""
    table = []
    for last in (0, 1):
        for run in range(5):
            for byte in range(256):
                stuffed, bit_last, bit_run = 0, last, run
                for shift in range(7, -1, -1):
                    bit = (byte >> shift) & 1
                    if bit == bit_last and bit_run:
                        bit_run += 1
                    else:
                        bit_run, bit_last = 1, bit
                    if bit_run == 5:
                        stuffed += 1
                        bit_last, bit_run = 1 - bit, 1
                table.append((stuffed, bit_last, bit_run))
    return table


_CRC_TABLE = _crc15_table()
_STUFF_TABLE = _stuff_table()


def _fast_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> int:
    """Same result as the string reference (``stuffed_section`` + ``stuff_bit_count``), table-driven."""
    rtr = 1 if is_remote else 0
    if is_extended:
        value = ((((arbitration_id >> 18) << 2 | 0b11) << 18 | (arbitration_id & 0x3FFFF)) << 3 | rtr << 2) << 4
        length = 39
    else:
        value = ((arbitration_id << 1 | rtr) << 2) << 4
        length = 19
    value |= dlc & 0xF
    if not is_remote and data:
        value = value << (8 * len(data)) | int.from_bytes(data, "big")
        length += 8 * len(data)
    # CRC-15 over SOF..data: the leading bits one by one, then whole bytes through the table.
    crc = 0
    lead = length % 8
    for shift in range(length - 1, length - 1 - lead, -1):
        feedback = ((value >> shift) & 1) ^ (crc >> 14)
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= CRC15_POLY
    for byte in (value & ((1 << (length - lead)) - 1)).to_bytes((length - lead) // 8, "big"):
        crc = ((crc << 8) & 0x7FFF) ^ _CRC_TABLE[((crc >> 7) ^ byte) & 0xFF]
    value = value << 15 | crc
    length += 15
    # Stuff bits over SOF..CRC, the same way.
    stuffed, last, run = 0, 0, 0
    lead = length % 8
    for shift in range(length - 1, length - 1 - lead, -1):
        bit = (value >> shift) & 1
        if bit == last and run:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:
            stuffed += 1
            last, run = 1 - bit, 1
    for byte in (value & ((1 << (length - lead)) - 1)).to_bytes((length - lead) // 8, "big"):
        added, last, run = _STUFF_TABLE[(last * 5 + run) * 256 + byte]
        stuffed += added
    return length + stuffed + TRAILER_BITS


def reference_bits(arbitration_id: int, is_extended: bool, is_remote: bool, dlc: int, data: bytes) -> int:
    """Bit by bit, for reading and for checking the table-driven count."""
    bits = stuffed_section(arbitration_id, is_extended, is_remote, dlc, data)
    return len(bits) + stuff_bit_count(bits) + TRAILER_BITS


_bits_cached = lru_cache(maxsize=CACHE_SIZE)(_fast_bits)


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
    return str(_bits_cached.cache_info())
