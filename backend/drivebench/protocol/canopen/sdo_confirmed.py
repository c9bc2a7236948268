"""Values that expedited SDO transfers on the bus confirmed, as a bus observer sees them (CiA 301 7.2.4.3).

A download counts once the server answers it (initiate download response, 0x60), with the data of the request; an
upload counts with the data of the server's expedited answer. An abort, or an answer for another object, ends the
pending transfer with nothing. Requests and answers pair by the low 7 bits of their COB-IDs, as on the default SDO
channels (0x600 + n / 0x580 + n) and the additional channels the seed devices use (0x640 + n / 0x5C0 + n).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Confirmed:
    channel: int
    """The low 7 bits of the channel's COB-IDs (the node id on a default SDO channel)."""
    index: int
    subindex: int
    value: int
    """The transferred bytes, little-endian."""


class ConfirmedValues:
    """Follows the SDO channels and reports each confirmed expedited transfer of an object ``wanted`` accepts."""

    def __init__(self, wanted: Callable[[int, int], bool]) -> None:
        self._wanted = wanted
        self._pending: dict[int, tuple[int, int, int | None]] = {}
        """channel -> (index, subindex, the download's value or None for an upload)."""

    def observe(self, cob_id: int, data: bytes | bytearray) -> Confirmed | None:
        if len(data) != 8:
            return None
        channel, command = cob_id & 0x7F, data[0]
        index, sub = data[1] | data[2] << 8, data[3]
        if cob_id >= 0x600:  # a request, client -> server
            specifier = command >> 5
            if specifier == 1 and command & 0x03 == 0x03 and self._wanted(index, sub):  # expedited, size given
                size = 4 - (command >> 2 & 3)
                self._pending[channel] = (index, sub, int.from_bytes(data[4:4 + size], "little"))
            elif specifier == 2 and self._wanted(index, sub):
                self._pending[channel] = (index, sub, None)
            elif specifier != 0 and specifier != 3:  # another transfer starts, or an abort (segments: 0, 3)
                self._pending.pop(channel, None)
            return None
        pending = self._pending.pop(channel, None)
        if pending is None or (index, sub) != pending[:2]:
            return None
        if command == 0x60 and pending[2] is not None:
            return Confirmed(channel, index, sub, pending[2])
        if command >> 5 == 2 and command & 0x03 == 0x03 and pending[2] is None:
            size = 4 - (command >> 2 & 3)
            return Confirmed(channel, index, sub, int.from_bytes(data[4:4 + size], "little"))
        return None
