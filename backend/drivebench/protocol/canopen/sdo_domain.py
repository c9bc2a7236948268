"""Download of a large DOMAIN (a program image to 0x1F50) by SDO block transfer, segmented where the device refuses
blocks, with progress and a cancel that aborts the transfer on the bus (CiA 301 7.2.4.3).

Written here rather than through canopen's ``BlockDownloadStream``/``WritableStream`` (canopen 2.4.1): those take
at most 7 bytes per ``write`` call and offer no way to stop a transfer midway that sends a proper abort (their
``abort`` leaves index and subindex 0, and closing a stream that is not done sends the end request and waits for
it). Frames still go through the channel's canopen ``SdoClient`` (its response queue, timeout and retries), under
the channel's lock.
"""

from __future__ import annotations

import binascii
import queue
import threading
import time
from collections.abc import Callable

import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from drivebench.protocol.canopen.sdo_client import carries_object, names_object, object_address

SEGMENT = 7
ABORT_BY_CLIENT = 0x08000000
"""CiA 301 "general error": the client ends the transfer on the user's cancel (CiA 301 has no code of its own)."""
INVALID_COMMAND = 0x05040001
UNSUPPORTED_ACCESS = 0x06010000
REFUSED_BLOCK = frozenset({INVALID_COMMAND, UNSUPPORTED_ACCESS})
"""A device that does not do block transfer answers the block initiate with one of these (canopen's LocalNode,
the simulator's expedited-only devices)."""
ANSWER_WAIT_S = 5.0
"""At least this long for each answer of a transfer, longer than the session's SDO timeout for one answer: a device
in the middle of a transfer it accepted is there, and a late answer (a busy device, a loaded host: a sub-block's
acknowledgement may wait until the block is in flash) must not fail a download that takes minutes. A device that
died mid-transfer costs this wait once. There is no retry: a segment sent again would be a toggle error."""
END_WAIT_S = 5.0
"""At least this long for the answer to the block end: many devices flash the whole image before they answer it."""
Progress = Callable[[int], None]


class TransferCancelled(Exception):
    """The caller cancelled; the device was sent an abort (``code``) and holds nothing of the transfer."""

    def __init__(self, sent: int, code: int) -> None:
        super().__init__(f"cancelled after {sent} bytes (abort 0x{code:08X})")
        self.sent = sent
        self.code = code


class _Download:
    def __init__(self, client: canopen.sdo.SdoClient, index: int, subindex: int, data: bytes,
                 progress: Progress, cancelled: threading.Event) -> None:
        self.client = client
        self.index = index
        self.subindex = subindex
        self.address = object_address(index, subindex)
        self.data = data
        self.progress = progress
        self.cancelled = cancelled
        self.sent = 0

    def forget_answers(self) -> None:
        """Nothing stale from an earlier transfer (canopen's client queues every answer on its COB-ID)."""
        responses = self.client.responses
        with responses.mutex:
            responses.queue.clear()

    def request(self, frame: bytes, at_least_s: float = ANSWER_WAIT_S, initiate: bool = False) -> bytes:
        self.client.send_request(frame)
        return self.answer(at_least_s, initiate)

    def answer(self, at_least_s: float = ANSWER_WAIT_S, initiate: bool = False) -> bytes:
        """The next answer within the channel's timeout or ``at_least_s``, whichever is longer; an abort raises
        ``SdoAbortedError``. The answer to an ``initiate`` names this object, and inside the transfer a frame that
        names an object (an abort, an initiate answer) names this one: one naming another is a late answer to an
        earlier request (sent again by its client after a timeout) and is passed over (a clean-clone run had a late
        "object does not exist" abort of another object end a program download midway)."""
        deadline = time.monotonic() + max(float(self.client.RESPONSE_TIMEOUT), at_least_s)
        while True:
            try:
                response = self.client.responses.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise SdoCommunicationError("No SDO response received") from None
            if names_object(response, self.address) or not (initiate or carries_object(response)):
                break
        if response[0] == 0x80:
            raise SdoAbortedError(int.from_bytes(response[4:8], "little"))
        return bytes(response)

    def abort(self, code: int) -> None:
        self.client.send_request(bytes([0x80]) + self.address + code.to_bytes(4, "little"))

    def check_cancel(self) -> None:
        if self.cancelled.is_set():
            self.abort(ABORT_BY_CLIENT)
            raise TransferCancelled(self.sent, ABORT_BY_CLIENT)

    def answer_of(self, response: bytes, command_mask: int, command: int) -> bytes:
        if response[0] & command_mask != command:
            self.abort(INVALID_COMMAND)
            raise SdoCommunicationError(f"Unexpected response 0x{response[0]:02X}")
        return response

    # --- block (CiA 301 7.2.4.3.9 ... 7.2.4.3.14) ---------------------------------------------------------------
    def block(self) -> None:
        size = len(self.data)
        start = bytes([0xC6]) + self.address + size.to_bytes(4, "little")  # crc, size indicated
        self.forget_answers()
        answer = self.answer_of(self.request(start, initiate=True), 0xE3, 0xA0)
        use_crc = bool(answer[0] & 0x04)
        block_size = answer[4]
        segments = max(1, -(-size // SEGMENT))
        first = 0  # the first segment of the current sub-block
        while first < segments:
            self.check_cancel()
            count = min(block_size, segments - first)
            for seq in range(1, count + 1):
                number = first + seq - 1
                piece = self.data[number * SEGMENT:(number + 1) * SEGMENT]
                last = number == segments - 1
                self.client.send_request(bytes([seq | (0x80 if last else 0)]) + piece.ljust(SEGMENT, b"\x00"))
                if not self.client.responses.empty():
                    break  # the device answered mid sub-block: an abort (it cannot take the data)
            ack = self.answer_of(self.answer(), 0xE3, 0xA2)
            acknowledged, block_size = ack[1], ack[2] or block_size
            first += min(acknowledged, count)  # an ack short of count: the rest of the sub-block again
            self.sent = min(first * SEGMENT, size)
            self.progress(self.sent)
        unused = segments * SEGMENT - size
        crc = binascii.crc_hqx(self.data, 0) if use_crc else 0
        end = bytes([0xC1 | unused << 2]) + crc.to_bytes(2, "little") + bytes(5)
        self.answer_of(self.request(end, END_WAIT_S), 0xE3, 0xA1)

    # --- segmented (CiA 301 7.2.4.3.3 ... 7.2.4.3.5) -------------------------------------------------------------
    def segmented(self) -> None:
        size = len(self.data)
        start = bytes([0x21]) + self.address + size.to_bytes(4, "little")
        self.forget_answers()
        self.answer_of(self.request(start, initiate=True), 0xFF, 0x60)
        toggle = 0
        position = 0
        while position < size or size == 0:
            if position % (SEGMENT * 128) == 0:
                self.check_cancel()
            piece = self.data[position:position + SEGMENT]
            last = position + SEGMENT >= size
            command = toggle << 4 | (SEGMENT - len(piece)) << 1 | (1 if last else 0)
            wait_s = END_WAIT_S if last else ANSWER_WAIT_S
            answer = self.request(bytes([command]) + piece.ljust(SEGMENT, b"\x00"), wait_s)
            self.answer_of(answer, 0xF0, 0x20 | toggle << 4)
            toggle ^= 1
            position += len(piece)
            self.sent = position
            if position % (SEGMENT * 128) == 0 or last:
                self.progress(position)
            if last:
                return


def download_domain(client: canopen.sdo.SdoClient, index: int, subindex: int, data: bytes, *,
                    block: bool = True, progress: Progress = lambda _sent: None,
                    cancelled: threading.Event | None = None) -> str:
    """Send ``data`` to ``index``/``subindex``: by block transfer (with CRC where the server offers it), segmented
    when ``block`` is off or the server refuses the block initiate. Returns ``"block"`` or ``"segmented"``; raises
    canopen's ``SdoAbortedError`` (the device aborted), ``SdoCommunicationError`` (no or a wrong answer) or
    :class:`TransferCancelled`. The caller holds the channel's lock."""
    transfer = _Download(client, index, subindex, data, progress, cancelled or threading.Event())
    if block:
        try:
            transfer.block()
            return "block"
        except SdoAbortedError as exc:
            if exc.code not in REFUSED_BLOCK or transfer.sent:
                raise
    transfer.segmented()
    return "segmented"
