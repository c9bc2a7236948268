"""Firmware files for the program download tests: Intel HEX written with intelhex, and one with a broken checksum."""

from __future__ import annotations

import io

from intelhex import IntelHex


def intel_hex(image: bytes, start: int = 0x8000) -> bytes:
    hex_file = IntelHex()
    hex_file.frombytes(image, offset=start)
    out = io.StringIO()
    hex_file.write_hex_file(out)
    return out.getvalue().encode("ascii")


def broken_checksum(hex_text: bytes, line: int) -> bytes:
    """``hex_text`` with the checksum byte of record ``line`` (1-based) changed."""
    lines = hex_text.decode("ascii").splitlines()
    record = lines[line - 1]
    wrong = (int(record[-2:], 16) + 1) & 0xFF
    lines[line - 1] = record[:-2] + f"{wrong:02X}"
    return ("\n".join(lines) + "\n").encode("ascii")
