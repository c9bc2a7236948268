"""The SDO server of a simulated drive: a CiA 301 protocol state machine over 8-byte frames.

No threads and no bus: the owner feeds every frame received on ``rx_cob`` to ``on_request`` and the server
answers through ``send(tx_cob, data)``. Values come from an ``ObjectAccess`` (the simulated object
dictionary), which signals refusals by raising ``SdoAbort(code)``.

Supported: expedited and segmented upload/download, block upload/download with CRC (CRC-16 CCITT, polynomial
0x1021, initial value 0, CiA 301 7.2.4.3.16) and the block upload protocol switch, abort from the client.
"""

from __future__ import annotations

import binascii
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

from drivebench.errors import ProtocolError
from drivebench.protocol.abort_codes import abort_text

TOGGLE_NOT_ALTERNATED = 0x05030000
INVALID_COMMAND = 0x05040001
INVALID_BLOCK_SIZE = 0x05040002
INVALID_SEQUENCE_NUMBER = 0x05040003
CRC_ERROR = 0x05040004
UNSUPPORTED_ACCESS = 0x06010000
LENGTH_DOES_NOT_MATCH = 0x06070010
LENGTH_TOO_HIGH = 0x06070012
LENGTH_TOO_LOW = 0x06070013
GENERAL_ERROR = 0x08000000

ABORT_COMMAND = 0x80
MAX_BLOCK_SIZE = 127
SEGMENT_DATA = 7
_INDEXED = struct.Struct("<BHB")  # command, index, subindex
_SIZE = struct.Struct("<I")


class SdoAbort(ProtocolError):
    """Raised by an ``ObjectAccess`` to refuse a read or write with a CiA 301 abort code."""

    def __init__(self, code: int, detail: str | None = None) -> None:
        super().__init__(detail or abort_text(code))
        self.code = code


class ObjectAccess(Protocol):
    """The object dictionary the server reads and writes; both raise ``SdoAbort`` to refuse."""

    def read(self, index: int, subindex: int) -> bytes: ...

    def write(self, index: int, subindex: int, data: bytes) -> None: ...


def crc16_ccitt(data: bytes) -> int:
    """CRC of a block transfer: CRC-16 CCITT, x^16 + x^12 + x^5 + 1, initial value 0 (CiA 301)."""
    return binascii.crc_hqx(data, 0)


# --- transfer states ---------------------------------------------------------------------------------------
@dataclass
class _Transfer:
    index: int
    subindex: int


@dataclass
class _SegmentedUpload(_Transfer):
    data: bytes
    position: int = 0
    toggle: int = 0


@dataclass
class _SegmentedDownload(_Transfer):
    size: int | None
    data: bytearray = field(default_factory=bytearray)
    toggle: int = 0


_Segmented = TypeVar("_Segmented", _SegmentedUpload, _SegmentedDownload)


@dataclass
class _BlockUpload(_Transfer):
    segments: list[bytes]
    crc: int
    block_size: int
    started: bool = False
    block_start: int = 0
    sent_in_block: int = 0
    ending: bool = False


@dataclass
class _BlockDownload(_Transfer):
    size: int | None
    use_crc: bool
    block_size: int
    data: bytearray = field(default_factory=bytearray)
    last_sequence: int = 0
    complete: bool = False


class SdoServer:
    """One SDO server channel (SDO1 ``0x600 + id``/``0x580 + id``; Lenze SDO2 ``0x640 + id``/``0x5C0 + id``).

    Device options: ``segmented`` and ``block`` say which transfers the device supports (MICROMASTER:
    neither); ``expedited_size_indicated`` makes expedited upload responses carry the size
    (``0x43``/``0x47``/``0x4B``/``0x4F``) rather than four bytes without size (``0x42``); ``block_size`` is
    the sub-block size the server asks for in block downloads; a transfer idle for ``timeout_s`` is dropped.
    """

    def __init__(self, node_id: int, send: Callable[[int, bytes], None], objects: ObjectAccess, *,
                 rx_cob: int | None = None, tx_cob: int | None = None, segmented: bool = True,
                 block: bool = True, expedited_size_indicated: bool = True,
                 block_size: int = MAX_BLOCK_SIZE, timeout_s: float = 1.0) -> None:
        if not 1 <= block_size <= MAX_BLOCK_SIZE:
            raise ValueError(f"block_size must be 1..{MAX_BLOCK_SIZE}, not {block_size}")
        self.node_id = node_id
        self.rx_cob = 0x600 + node_id if rx_cob is None else rx_cob
        self.tx_cob = 0x580 + node_id if tx_cob is None else tx_cob
        self.segmented = segmented
        self.block = block
        self.expedited_size_indicated = expedited_size_indicated
        self.block_size = block_size
        self._send = send
        self._objects = objects
        self.timeout_s = timeout_s
        self._transfer: _Transfer | None = None
        self._last_request = 0.0
        self._last_reply = 0.0
        self._handlers: dict[int, Callable[[bytes], None]] = {
            0: self._download_segment,
            1: self._initiate_download,
            2: self._initiate_upload,
            3: self._upload_segment,
            5: self._block_upload,
            6: self._block_download,
        }

    @property
    def busy(self) -> bool:
        """True while a segmented or block transfer is in progress."""
        return self._transfer is not None

    @property
    def expects_segment(self) -> bool:
        """True while a block download's sub-block comes in: the next frame is a segment (or an abort)."""
        transfer = self._transfer
        return isinstance(transfer, _BlockDownload) and not transfer.complete

    def reset(self) -> None:
        """Forget a transfer in progress (client abort, NMT reset, server timeout)."""
        self._transfer = None

    def on_request(self, data: bytes, now: float | None = None) -> None:
        """Handle one frame received on ``rx_cob`` (``now``: when it was on the bus, in seconds on one clock for all
        of this server's requests, else ``time.monotonic()``; a server that handles its requests from a queue passes
        it, so a backlog is not taken for an idle client)."""
        if len(data) != 8:
            return  # CiA 301: SDO frames have 8 data bytes; others are not SDO requests.
        now = time.monotonic() if now is None else now
        idle = now - self._last_request > self.timeout_s and time.monotonic() - self._last_reply > self.timeout_s
        if self._transfer is not None and idle:
            # SDO server timeout: a client that vanished mid-transfer (no abort sent) must not block the channel.
            self.reset()
        self._last_request = now
        transfer = self._transfer
        sub_block = transfer if isinstance(transfer, _BlockDownload) and not transfer.complete else None
        # In a block download sub-block every frame is a segment (0x85: last segment, seqno 5); 0x80 aborts.
        if data[0] == ABORT_COMMAND or (data[0] >> 5 == 4 and sub_block is None):
            self.reset()
            return
        try:
            if sub_block is not None:
                self._block_download_segment(sub_block, data)
                return
            command_specifier = data[0] >> 5
            handler = self._handlers.get(command_specifier)
            if handler is None or (command_specifier in (5, 6) and not self.block):
                raise SdoAbort(INVALID_COMMAND)
            handler(data)
        except SdoAbort as abort:
            self._abort(data, abort.code)

    # --- expedited and segmented upload -------------------------------------------------------------------
    def _initiate_upload(self, request: bytes) -> None:
        _, index, subindex = _INDEXED.unpack_from(request)
        self._transfer = None
        self._answer_upload(index, subindex, self._objects.read(index, subindex))

    def _answer_upload(self, index: int, subindex: int, value: bytes) -> None:
        """Initiate upload response: expedited for 1..4 bytes, else the start of a segmented upload."""
        if 1 <= len(value) <= 4:
            command = 0x43 | (4 - len(value)) << 2 if self.expedited_size_indicated else 0x42
            self._reply(_INDEXED.pack(command, index, subindex) + value.ljust(4, b"\x00"))
            return
        if not self.segmented:
            # An expedited-only device (MICROMASTER) cannot return more than 4 bytes; the manual does not say
            # which code it answers, CiA 301's "unsupported access" is the closest.
            raise SdoAbort(UNSUPPORTED_ACCESS)
        self._transfer = _SegmentedUpload(index, subindex, value)
        self._reply(_INDEXED.pack(0x41, index, subindex) + _SIZE.pack(len(value)))

    def _segment_of(self, request: bytes, kind: type[_Segmented]) -> tuple[_Segmented, int]:
        """The segmented transfer a segment request belongs to and the request's toggle bit: a transfer of ``kind``
        must be under way and the toggle bit alternated."""
        transfer = self._transfer
        if not isinstance(transfer, kind):
            raise SdoAbort(INVALID_COMMAND)
        toggle = request[0] >> 4 & 1
        if toggle != transfer.toggle:
            raise SdoAbort(TOGGLE_NOT_ALTERNATED)
        return transfer, toggle

    def _upload_segment(self, request: bytes) -> None:
        transfer, toggle = self._segment_of(request, _SegmentedUpload)
        chunk = transfer.data[transfer.position:transfer.position + SEGMENT_DATA]
        transfer.position += len(chunk)
        last = transfer.position >= len(transfer.data)
        command = toggle << 4 | (SEGMENT_DATA - len(chunk)) << 1 | int(last)
        self._reply(bytes([command]) + chunk.ljust(SEGMENT_DATA, b"\x00"))
        transfer.toggle ^= 1
        if last:
            self._transfer = None

    # --- expedited and segmented download -----------------------------------------------------------------
    def _initiate_download(self, request: bytes) -> None:
        command, index, subindex = _INDEXED.unpack_from(request)
        self._transfer = None
        expedited, size_indicated = command & 0x02, command & 0x01
        if expedited:
            # e = 1, s = 0: "unspecified number of bytes" - the whole four (MICROMASTER traces use 0x22).
            length = 4 - (command >> 2 & 3) if size_indicated else 4
            self._objects.write(index, subindex, bytes(request[4:4 + length]))
            self._reply(_INDEXED.pack(0x60, index, subindex) + bytes(4))
            return
        if not self.segmented:
            raise SdoAbort(INVALID_COMMAND)
        size = _SIZE.unpack_from(request, 4)[0] if size_indicated else None
        self._transfer = _SegmentedDownload(index, subindex, size)
        self._reply(_INDEXED.pack(0x60, index, subindex) + bytes(4))

    def _download_segment(self, request: bytes) -> None:
        transfer, toggle = self._segment_of(request, _SegmentedDownload)
        unused = request[0] >> 1 & 7
        transfer.data += request[1:8 - unused]
        if transfer.size is not None and len(transfer.data) > transfer.size:
            raise SdoAbort(LENGTH_TOO_HIGH)
        if request[0] & 0x01:
            _check_size(transfer.size, len(transfer.data))
            self._objects.write(transfer.index, transfer.subindex, bytes(transfer.data))
            self._transfer = None
        else:
            transfer.toggle ^= 1
        self._reply(bytes([0x20 | toggle << 4]) + bytes(7))

    # --- block upload (client command specifier 5) --------------------------------------------------------
    def _block_upload(self, request: bytes) -> None:
        subcommand = request[0] & 0x03
        if subcommand == 0:
            self._initiate_block_upload(request)
            return
        transfer = self._transfer
        if not isinstance(transfer, _BlockUpload):
            raise SdoAbort(INVALID_COMMAND)
        if subcommand == 3 and not transfer.started:
            transfer.started = True
            self._send_sub_block(transfer)
        elif subcommand == 2 and transfer.started and not transfer.ending:
            self._block_upload_ack(transfer, ackseq=request[1], block_size=request[2])
        elif subcommand == 1 and transfer.ending:
            self._transfer = None
        else:
            raise SdoAbort(INVALID_COMMAND)

    def _initiate_block_upload(self, request: bytes) -> None:
        _, index, subindex = _INDEXED.unpack_from(request)
        block_size, switch_threshold = request[4], request[5]
        self._transfer = None
        if not 1 <= block_size <= MAX_BLOCK_SIZE:
            raise SdoAbort(INVALID_BLOCK_SIZE)
        value = self._objects.read(index, subindex)
        if switch_threshold and len(value) <= switch_threshold:
            # Protocol switch (CiA 301): small values go back as a normal expedited/segmented upload.
            self._answer_upload(index, subindex, value)
            return
        segments = [value[i:i + SEGMENT_DATA] for i in range(0, len(value), SEGMENT_DATA)] or [b""]
        self._transfer = _BlockUpload(index, subindex, segments, crc16_ccitt(value), block_size)
        # scs 6, sc = 1 (server generates a CRC), s = 1 (size indicated), ss = 0
        self._reply(_INDEXED.pack(0xC6, index, subindex) + _SIZE.pack(len(value)))

    def _send_sub_block(self, transfer: _BlockUpload) -> None:
        block = transfer.segments[transfer.block_start:transfer.block_start + transfer.block_size]
        for sequence, chunk in enumerate(block, start=1):
            last = transfer.block_start + sequence == len(transfer.segments)
            self._reply(bytes([sequence | (0x80 if last else 0)]) + chunk.ljust(SEGMENT_DATA, b"\x00"))
        transfer.sent_in_block = len(block)

    def _block_upload_ack(self, transfer: _BlockUpload, ackseq: int, block_size: int) -> None:
        if ackseq > transfer.sent_in_block:
            raise SdoAbort(INVALID_SEQUENCE_NUMBER)
        if not 1 <= block_size <= MAX_BLOCK_SIZE:
            raise SdoAbort(INVALID_BLOCK_SIZE)
        transfer.block_start += ackseq  # segments after ackseq are sent again in the next sub-block
        transfer.block_size = block_size
        if transfer.block_start < len(transfer.segments):
            self._send_sub_block(transfer)
            return
        transfer.ending = True
        unused = SEGMENT_DATA - len(transfer.segments[-1])
        self._reply(bytes([0xC1 | unused << 2]) + struct.pack("<H", transfer.crc) + bytes(5))

    # --- block download (client command specifier 6) ------------------------------------------------------
    def _block_download(self, request: bytes) -> None:
        if request[0] & 0x01 == 0:
            self._initiate_block_download(request)
            return
        transfer = self._transfer
        if not isinstance(transfer, _BlockDownload):
            raise SdoAbort(INVALID_COMMAND)
        self._end_block_download(transfer, request)

    def _initiate_block_download(self, request: bytes) -> None:
        command, index, subindex = _INDEXED.unpack_from(request)
        size = _SIZE.unpack_from(request, 4)[0] if command & 0x02 else None
        use_crc = bool(command & 0x04)
        # A zero-size download has no sub-block: the next frame is already the end request (CiA 301 allows it).
        self._transfer = _BlockDownload(index, subindex, size, use_crc, self.block_size, complete=size == 0)
        # scs 5, sc = 1 (server checks a CRC), ss = 0; byte 4 = blksize
        self._reply(_INDEXED.pack(0xA4, index, subindex) + bytes([self.block_size, 0, 0, 0]))

    def _block_download_segment(self, transfer: _BlockDownload, segment: bytes) -> None:
        sequence, last = segment[0] & 0x7F, bool(segment[0] & 0x80)
        if sequence == 0:
            raise SdoAbort(INVALID_SEQUENCE_NUMBER)
        if sequence == transfer.last_sequence + 1:
            transfer.last_sequence = sequence
            transfer.data += segment[1:8]
            transfer.complete = last
        # Out-of-order segments are dropped; the acknowledgement names the last good one, the client repeats.
        if sequence >= transfer.block_size or last:
            self._reply(bytes([0xA2, transfer.last_sequence, transfer.block_size]) + bytes(5))
            transfer.last_sequence = 0

    def _end_block_download(self, transfer: _BlockDownload, request: bytes) -> None:
        if not transfer.complete:
            raise SdoAbort(INVALID_COMMAND)
        unused = request[0] >> 2 & 7
        data = bytes(transfer.data[:len(transfer.data) - unused])
        if transfer.use_crc and struct.unpack_from("<H", request, 1)[0] != crc16_ccitt(data):
            raise SdoAbort(CRC_ERROR)
        _check_size(transfer.size, len(data))
        self._objects.write(transfer.index, transfer.subindex, data)
        self._transfer = None
        self._reply(bytes([0xA1]) + bytes(7))

    # --- frames -------------------------------------------------------------------------------------------
    def _reply(self, data: bytes) -> None:
        # the idle time of a transfer also counts from the server's own last answer (a block acknowledgement sent
        # after a long backlog is where the client's next sub-block starts from)
        self._last_reply = time.monotonic()
        self._send(self.tx_cob, data)

    def _abort(self, request: bytes, code: int) -> None:
        """Send an abort naming the transfer's object and end the transfer.

        With no transfer in progress the abort repeats the request's index and subindex, except for segment
        requests (command specifiers 0 and 3), which carry no index.
        """
        if self._transfer is not None:
            index, subindex = self._transfer.index, self._transfer.subindex
        elif request[0] >> 5 in (0, 3):
            index = subindex = 0
        else:
            _, index, subindex = _INDEXED.unpack_from(request)
        self._transfer = None
        self._reply(_INDEXED.pack(ABORT_COMMAND, index, subindex) + _SIZE.pack(code))


def _check_size(indicated: int | None, received: int) -> None:
    if indicated is None or indicated == received:
        return
    raise SdoAbort(LENGTH_TOO_HIGH if received > indicated else LENGTH_TOO_LOW)
