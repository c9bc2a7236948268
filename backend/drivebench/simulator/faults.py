"""SDO faults a simulated node can be told to show, switchable while it runs (tests and demos).

The node applies them around its SDO server (``node.py``): requests are dropped or aborted before the server
sees them, answers are altered on their way to the bus. The server's own state machine stays correct, so
clearing a fault is all it takes for the node to answer properly again.
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass, fields, replace

from drivebench.errors import InvalidValue
from drivebench.i18n import N_, _, number

_INDEXED_COMMANDS = (1, 2, 5, 6)
"""Client command specifiers whose requests name an object: initiate download/upload, block download/upload."""
_DOWNLOAD_COMMANDS = (1, 6)
"""Initiate download and block download."""
ABORT_CODE_RANGE = N_("abort_code must be a 32-bit CiA 301 abort code")


@dataclass(frozen=True)
class SdoFaults:
    """The faults of one node; all off by default."""

    silent_after_segments: int | None = None
    """Answer this many segment requests of a segmented transfer, then no more until the next transfer starts."""
    wrong_toggle: bool = False
    """Segment answers carry the toggle bit the client did not ask for."""
    index_offset: int = 0
    """Answers that name an object name ``index + index_offset`` instead (0: off)."""
    subindex_offset: int = 0
    """Answers that name an object name ``subindex + subindex_offset`` instead (0: off)."""
    abort_code: int | None = None
    """Abort requests that start a transfer with this CiA 301 code (None: off)..."""
    abort_every: int = 1
    """...every one of them (1) or every n-th."""
    abort_index: int | None = None
    """...only those naming this object index (None: any object)."""
    latency_ms: float = 0.0
    """Extra processing time per SDO request..."""
    late_requests: int = 0
    """...for every request (0), or only for the next this many requests that start a transfer (a busy device
    answering a few requests after the client gave up on them)."""
    drop_requests: int = 0
    """Leave the next this many requests that start a transfer unanswered (lost frames), then answer again."""
    drop_downloads: int = 0
    """Leave the next this many download requests unanswered (a device busy writing its memory), then answer
    again; uploads are answered meanwhile."""
    lost_download_answers: int = 0
    """Write the values of the next this many expedited downloads (up to 4 bytes) but lose the answer that confirms
    each (the device holds the new value, the client hears nothing), then answer again."""
    flash_error: int | None = None
    """The next program download (0x1F50) fails to flash with this CiA 302-3 0x1F57 error code (1 ... 127)."""
    power_loss_mid_flash: bool = False
    """The power fails while the next program download is flashed: the device comes back in its bootloader."""

    def __post_init__(self) -> None:
        if self.silent_after_segments is not None and self.silent_after_segments < 0:
            raise InvalidValue(_("{field} must be 0 or more").format(field="silent_after_segments"))
        if self.abort_code is not None and not 0 < self.abort_code <= 0xFFFFFFFF:
            raise InvalidValue(_(ABORT_CODE_RANGE))
        if self.abort_every < 1:
            raise InvalidValue(_("abort_every must be 1 or more"))
        if (self.late_requests < 0 or self.drop_requests < 0 or self.drop_downloads < 0
                or self.lost_download_answers < 0):
            raise InvalidValue(_("{field} must be 0 or more").format(
                field="late_requests, drop_requests, drop_downloads, lost_download_answers"))
        if not 0 <= self.latency_ms <= 60_000:
            raise InvalidValue(_("latency_ms must be 0 ... 60000"))
        if self.abort_index is not None and not 0 <= self.abort_index <= 0xFFFF:
            raise InvalidValue(_("abort_index must be 0 ... 0xFFFF"))
        if self.flash_error is not None and not 1 <= self.flash_error <= 127:
            raise InvalidValue(_("flash_error must be a 0x1F57 error code 1 ... 127"))
        if not -0xFFFF <= self.index_offset <= 0xFFFF or not -0xFF <= self.subindex_offset <= 0xFF:
            raise InvalidValue(_("index_offset must be within ±0xFFFF and subindex_offset within ±0xFF"))

    @property
    def active(self) -> bool:
        return self != SdoFaults()

    def as_dict(self) -> dict[str, object]:
        return asdict(self)

    def describe(self) -> list[str]:
        """The active faults in words (the simulator's fault panel and logs)."""
        words = []
        if self.silent_after_segments is not None:
            words.append(_("stops answering after {count} segments of a segmented transfer").format(
                count=self.silent_after_segments))
        if self.wrong_toggle:
            words.append(_("answers segments with the wrong toggle bit"))
        if self.index_offset or self.subindex_offset:
            words.append(_("answers name another object (index {index}, subindex {subindex})").format(
                index=f"{self.index_offset:+d}", subindex=f"{self.subindex_offset:+d}"))
        if self.abort_code is not None:
            aborts = (_("aborts every request with {code}") if self.abort_every == 1
                      else _("aborts every {n}th request with {code}"))
            words.append(aborts.format(n=self.abort_every, code=f"0x{self.abort_code:08X}"))
            if self.abort_index is not None:
                words.append(_("aborts only requests for object 0x{index:04X}").format(index=self.abort_index))
        if self.latency_ms:
            latency = (_("{ms} ms extra SDO latency on the next {count} requests") if self.late_requests
                       else _("{ms} ms extra SDO latency"))
            words.append(latency.format(ms=number(self.latency_ms), count=self.late_requests))
        if self.drop_requests:
            words.append(_("leaves the next {count} requests unanswered").format(count=self.drop_requests))
        if self.drop_downloads:
            words.append(_("leaves the next {count} download requests unanswered").format(count=self.drop_downloads))
        if self.lost_download_answers:
            words.append(_("writes the next {count} expedited downloads but loses their answers").format(
                count=self.lost_download_answers))
        if self.flash_error is not None:
            words.append(_("fails to flash the next program download (flash error {code})").format(
                code=self.flash_error))
        if self.power_loss_mid_flash:
            words.append(_("loses power while flashing the next program download"))
        return words


FAULT_NAMES = frozenset(f.name for f in fields(SdoFaults))


@dataclass
class _ChannelCounters:
    transfers: int = 0
    segments_answered: int = 0
    block_upload_running: bool = False
    lose_answer: bool = False
    """The answer to the running expedited download is lost (``lost_download_answers``)."""


class FaultState:
    """A node's active faults and the counters they need (per SDO channel); read by the node's SDO workers,
    set from anywhere."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._faults = SdoFaults()
        self._channels: dict[int, _ChannelCounters] = {}
        self._late_left = 0
        self._drops_left = 0
        self._download_drops_left = 0
        self._answers_to_lose = 0

    @property
    def faults(self) -> SdoFaults:
        return self._faults

    def set(self, faults: SdoFaults | None = None, **changes: object) -> SdoFaults:
        """Replace the faults (``set(SdoFaults(...))``), change some (``set(wrong_toggle=True)``), or clear
        them all (``set()``)."""
        unknown = set(changes) - FAULT_NAMES
        if unknown:
            raise InvalidValue(_("unknown fault(s): {names}").format(names=", ".join(sorted(unknown))))
        base = faults if faults is not None else (self._faults if changes else SdoFaults())
        new = replace(base, **changes)  # type: ignore[arg-type]
        with self._lock:
            self._faults = new
            self._channels.clear()
            self._late_left = new.late_requests
            self._drops_left = new.drop_requests
            self._download_drops_left = new.drop_downloads
            self._answers_to_lose = new.lost_download_answers
        return new

    def clear(self) -> None:
        self.set()

    # --- used by the node's SDO workers ----------------------------------------------------------------
    def delay_s(self, request: bytes) -> float:
        """Extra processing time for this request (``latency_ms``, or only for the next ``late_requests``)."""
        faults = self._faults
        if not faults.latency_ms:
            return 0.0
        if not faults.late_requests:
            return faults.latency_ms / 1000
        with self._lock:
            if self._late_left and _starts_transfer(request):
                self._late_left -= 1
                return faults.latency_ms / 1000
        return 0.0

    def segment_delay_s(self) -> float:
        """Extra processing time for a block download segment: ``latency_ms`` where every request has it."""
        faults = self._faults
        return faults.latency_ms / 1000 if faults.latency_ms and not faults.late_requests else 0.0

    def on_request(self, channel: int, request: bytes) -> int | None:
        """None to pass the request on, 0 to drop it (silence), or an abort code to answer with."""
        faults = self._faults
        command = request[0] >> 5
        with self._lock:
            counters = self._channels.setdefault(channel, _ChannelCounters())
            counters.block_upload_running = command == 5 and request[0] & 0x03 in (2, 3)
            if _starts_transfer(request):
                counters.segments_answered = 0
                if self._drops_left:
                    self._drops_left -= 1
                    return 0
                if self._download_drops_left and command in _DOWNLOAD_COMMANDS:
                    self._download_drops_left -= 1
                    return 0
                counters.lose_answer = command == 1 and bool(request[0] & 0x02) and self._answers_to_lose > 0
                if counters.lose_answer:
                    self._answers_to_lose -= 1
                named = int.from_bytes(request[1:3], "little")
                if faults.abort_code is not None and faults.abort_index in (None, named):
                    counters.transfers += 1
                    if counters.transfers % faults.abort_every == 0:
                        return faults.abort_code
                return None
            if command in (0, 3) and faults.silent_after_segments is not None:
                if counters.segments_answered >= faults.silent_after_segments:
                    return 0
                counters.segments_answered += 1
        return None

    def on_answer(self, channel: int, answer: bytes) -> bytes | None:
        """The answer as the faulty node sends it (None: lost)."""
        faults = self._faults
        counters = self._channels.get(channel)
        if counters is not None and counters.lose_answer:
            counters.lose_answer = False
            if answer[0] == 0x60:  # the expedited download's response: the value is written
                return None
        if not faults.wrong_toggle and not faults.index_offset and not faults.subindex_offset:
            return answer
        if counters is not None and counters.block_upload_running:
            return answer  # sub-block segments start with a sequence number, not a command
        data = bytearray(answer)
        names_object = _names_object(answer)
        if faults.wrong_toggle and answer[0] >> 5 in (0, 1) and not names_object:
            data[0] ^= 0x10  # upload segment (scs 0) and download segment (scs 1) answers carry the toggle
        if (faults.index_offset or faults.subindex_offset) and names_object:
            index = (int.from_bytes(answer[1:3], "little") + faults.index_offset) & 0xFFFF
            data[1:3] = index.to_bytes(2, "little")
            data[3] = (answer[3] + faults.subindex_offset) & 0xFF
        return bytes(data)


def _starts_transfer(request: bytes) -> bool:
    return request[0] >> 5 in _INDEXED_COMMANDS and not _is_block_follow_up(request)


def _is_block_follow_up(request: bytes) -> bool:
    """Block upload start/ack/end (ccs 5, cs != 0) and block download end (ccs 6, cs = 1) carry no new object."""
    command = request[0] >> 5
    return (command == 5 and request[0] & 0x03 != 0) or (command == 6 and request[0] & 0x01 == 1)


def _names_object(answer: bytes) -> bool:
    """Initiate answers (upload 0x4x, download 0x60, block 0xA4/0xC6) and aborts carry index and subindex."""
    command = answer[0]
    return command >> 5 in (2, 3) or command in (0x80, 0xA4, 0xC2, 0xC6)


__all__ = ["FAULT_NAMES", "FaultState", "SdoFaults"]
