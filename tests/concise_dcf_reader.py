"""A concise DCF reader written from CiA 302-3 alone (object 0x1F22's value), shared by no code with DriveBench's
encoder/decoder: it checks their bytes independently.

CiA 302-3, 0x1F22 (Concise DCF), data layout, all fields little endian:
  UNSIGNED32  number of entries
  per entry:  UNSIGNED16 index, UNSIGNED8 sub-index, UNSIGNED32 size of the data in bytes, the data (size bytes)
"""

from __future__ import annotations


def read_concise_dcf(data: bytes) -> list[tuple[int, int, bytes]]:
    count = data[0] | data[1] << 8 | data[2] << 16 | data[3] << 24
    at = 4
    entries = []
    for _ in range(count):
        index = data[at] | data[at + 1] << 8
        sub = data[at + 2]
        size = data[at + 3] | data[at + 4] << 8 | data[at + 5] << 16 | data[at + 6] << 24
        at += 7
        assert at + size <= len(data), "entry runs past the end"
        entries.append((index, sub, bytes(data[at:at + size])))
        at += size
    assert at == len(data), "bytes after the last entry"
    return entries
