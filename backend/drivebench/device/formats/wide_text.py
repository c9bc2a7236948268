"""UTF-16 and UTF-32 text files (a byte order mark, or none): which encoding, and the text.

Windows tools save EDS and XDD files as "Unicode" (UTF-16 LE with a BOM) and some generators without the BOM. Text
of a device description is mostly ASCII, so without a BOM the NUL bytes tell: every second byte NUL is UTF-16,
three of four is UTF-32, and which of them is NUL gives the byte order.
"""

from __future__ import annotations

_BOMS = ((b"\xff\xfe\x00\x00", "utf-32-le"), (b"\x00\x00\xfe\xff", "utf-32-be"),
         (b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be"))
_SAMPLE_BYTES = 4096
_NUL_SHARE = 0.9
"""The share of the expected NUL positions that must hold NUL (ASCII text in a wide encoding: all of them)."""


def wide_encoding(data: bytes) -> str | None:
    """``utf-16-le``, ``utf-16-be``, ``utf-32-le`` or ``utf-32-be`` when ``data`` is text in one of them, else None."""
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            return encoding
    sample = data[:_SAMPLE_BYTES]
    if len(sample) < 8 or sample.count(0) < len(sample) // 3:
        return None
    for encoding, width, text_at in (("utf-32-le", 4, 0), ("utf-32-be", 4, 3), ("utf-16-le", 2, 0),
                                     ("utf-16-be", 2, 1)):
        usable = sample[:len(sample) - len(sample) % width]
        units = [usable[i:i + width] for i in range(0, len(usable), width)]
        nul_places = sum(1 for unit in units for at, byte in enumerate(unit) if at != text_at and byte == 0)
        text_bytes = sum(1 for unit in units if unit[text_at] != 0)
        if nul_places >= _NUL_SHARE * len(units) * (width - 1) and text_bytes >= _NUL_SHARE * len(units):
            return encoding
    return None


def decode_wide(data: bytes) -> str | None:
    """The text of a UTF-16/32 file (BOM removed), or None when it is not one (or does not decode)."""
    encoding = wide_encoding(data)
    if encoding is None:
        return None
    body = data
    for bom, name in _BOMS:
        if name == encoding and data.startswith(bom):
            body = data[len(bom):]
            break
    try:
        return body.decode(encoding)
    except UnicodeDecodeError:
        return None
