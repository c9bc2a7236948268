"""Expedited (and segmented) SDO upload awaited on the event loop, without a worker thread per read.

:func:`upload_expedited` sends the CiA 301 initiate-upload request on one of a node's SDO channels and awaits the
response, which the bus reader thread hands to the loop; with ``segmented`` it also asks for the segments of a
segmented answer, from the bus reader thread as each segment arrives (a string, a long record: no hop to the
loop per segment). It answers ``None`` where it
cannot do the transfer itself (the channel is busy with another transfer, or the device answers segmented and
``segmented`` is off): the caller then uses
:meth:`NodeClient.upload <drivebench.protocol.canopen.network.NodeClient.upload>` in a worker thread.

Timeout and retries are the channel's own (``NodeClient.configure``), read at every call, as canopen's client
reads them.
"""

from __future__ import annotations

import asyncio
import enum
import threading
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

from drivebench.errors import ProtocolError, SdoAbortError, SdoOutOfStepError, SdoStalledError, SdoTimeoutError
from drivebench.i18n import Text
from drivebench.protocol.abort_codes import abort_text
from drivebench.protocol.canopen.network import NodeClient, SdoChannel
from drivebench.protocol.canopen.sdo_client import names_object, object_address
from drivebench.protocol.canopen.sdo_errors import NO_RESPONSE, UNEXPECTED, reason
from drivebench.protocol.loop_handoff import Response, hand_over, waker

ABORT_TIMEOUT = 0x05040000
"""CiA 301: SDO protocol timed out (sent when the last attempt got no answer)."""
ABORT_TOGGLE = 0x05030000
"""CiA 301: toggle bit not alternated."""
SEGMENT_DATA = 7
"""Data bytes of one SDO segment."""
ABORT_INVALID_COMMAND = 0x05040001
"""CiA 301: command specifier not valid (sent to end a segmented answer this path does not handle)."""
MAX_LATE_ANSWERS = 4
"""Late answers to earlier requests that each give the request waiting one more timeout."""


class ExpeditedRequest:
    """One object's initiate-upload request, built once and reused for every read of that object."""

    __slots__ = ("address", "frame", "index", "subindex")

    def __init__(self, index: int, subindex: int) -> None:
        self.index = index
        self.subindex = subindex
        self.address = object_address(index, subindex)
        """Index (little endian) and subindex as every frame of the transfer carries them (bytes 1..3)."""
        self.frame = b"\x40" + self.address + bytes(4)  # CiA 301 initiate upload


class Outcome(enum.Enum):
    """How one request of a transfer ended, as the bus reader thread saw it."""

    VALUE = "value"
    ABORTED = "aborted"
    """The device aborted (its code in ``Ended.code``)."""
    FOR_THE_BLOCKING_CLIENT = "blocking"
    """An answer this path does not read (segmented where segments were not asked for): the transfer was aborted
    with 0x05040001 and the caller reads it with canopen's client."""
    UNEXPECTED = "unexpected"
    """A segment answer with another command (aborted with 0x05040001)."""
    TOGGLE = "toggle"
    """A segment answer with the wrong toggle bit (aborted with 0x05030000)."""
    SILENT = "silent"
    """No answer in any attempt (aborted with 0x05040000)."""


@dataclass(frozen=True)
class Ended:
    outcome: Outcome
    data: bytes = b""
    code: int = 0
    """The abort code (ABORTED) or the command byte (UNEXPECTED)."""
    stalled: bool = False
    """SILENT after the initiate answer: the segments stopped."""
    segments: int = 0
    total: int | None = None
    """Segments received and announced (a stalled transfer)."""
    other_object: bytes | None = None
    """SILENT: the address an answer for another object named meanwhile."""


class _Transfer:
    """Uploads in progress on a channel (one, or a batch one after the other), advanced by the bus reader thread
    as each answer arrives.

    The reader thread asks for a segmented answer's segments right there, and in a batch sends the next object's
    request as soon as one ends (as a device's own SDO server answers): the event loop hears only the end of the
    whole transfer, one wake-up instead of one per segment and per object. ``lock`` orders the reader thread's steps
    against the loop's timeouts and retries."""

    __slots__ = ("deadline", "ended", "finished", "frame", "last_progress", "lock", "other_object", "phase",
                 "position", "requests", "response", "segmented", "size", "stale", "toggle", "tried", "value")

    INITIATE, SEGMENTS = 0, 1

    def __init__(self, requests: Sequence[ExpeditedRequest], segmented: Sequence[bool]) -> None:
        self.lock = threading.Lock()
        self.requests = requests
        self.segmented = segmented
        self.ended: list[Ended] = []
        self.position = 0
        self.response: Response | None = None
        self.finished = True
        """The current ``response`` is resolved: answers are ignored until the loop sends again."""
        self.deadline = 0.0
        """``time.monotonic()`` by which the answer to ``frame`` is due."""
        self.tried = 0
        """Attempts that timed out at ``last_progress`` (attempts count per request, and per segment)."""
        self._start()
        self.last_progress = self.progress()

    def _start(self) -> None:
        self.phase = self.INITIATE
        self.frame = self.requests[self.position].frame
        """The request the transfer waits on (sent again, as it is, when an attempt times out)."""
        self.size: int | None = None
        self.value = bytearray()
        self.toggle = 0
        self.other_object: bytes | None = None
        self.stale = 0
        """Answers naming another object while this request waited (late answers to earlier requests)."""

    @property
    def request(self) -> ExpeditedRequest:
        return self.requests[self.position]

    def progress(self) -> tuple[int, int, int]:
        return self.position, self.phase, len(self.value)

    def end(self, ended: Ended) -> bool:
        """Record how the current request ended; True when another one follows (its state is set up)."""
        self.ended.append(ended)
        self.position += 1
        if self.position < len(self.requests):
            self._start()
            return True
        return False

    def stalled(self) -> Ended:
        if self.phase == self.SEGMENTS:
            total = -(-self.size // SEGMENT_DATA) if self.size else None
            return Ended(Outcome.SILENT, stalled=True, segments=len(self.value) // SEGMENT_DATA, total=total)
        return Ended(Outcome.SILENT, other_object=self.other_object)


class ExpeditedUploader:
    """SDO upload on one SDO channel, awaited on the event loop: the request is sent, the answer resolves a
    :class:`~drivebench.protocol.loop_handoff.Response` from the bus reader thread (with ``segmented``, after the
    reader thread has asked for every segment; a batch after the last object). No worker thread per read, so the
    service layer keeps pace with a bare canopen client.

    It takes the channel's lock without waiting (a transfer in progress or transfers waiting send the read to a
    worker thread instead, to wait its turn) and checks that the response names the requested object; canopen's
    own client on the same COB-ID discards the copy it queued at its next transfer. The SDO timeout is one
    watchdog timer per channel that re-arms itself, not a timer per read.
    """

    def __init__(self, client: NodeClient, channel: SdoChannel) -> None:
        # no reference to the channel or the node client: they key ``_UPLOADERS`` weakly
        self.node_id = client.node_id
        self.abort_texts = client.abort_texts
        self.lock = channel.lock
        self.sdo = channel.client
        self._transfer: _Transfer | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timeout = 0.0
        self._attempts = 1
        self._watch: asyncio.TimerHandle | None = None
        self._watch_loop: asyncio.AbstractEventLoop | None = None
        self._watch_at = 0.0
        self.sdo.network.subscribe(self.sdo.tx_cobid, self._on_response)

    # --- the bus reader thread --------------------------------------------------------------------------------
    def _on_response(self, can_id: int, data: bytearray, timestamp: float) -> None:
        transfer = self._transfer
        if transfer is None:
            return
        with transfer.lock:
            if transfer.finished:
                return
            ended = self._step(transfer, data)
            if ended is None:
                return
            if transfer.end(ended):
                self._send(transfer, transfer.frame)
                return
            transfer.finished = True
            response, loop = transfer.response, self._loop
        assert response is not None and loop is not None
        hand_over(loop, response, b"")

    def _step(self, transfer: _Transfer, data: bytearray) -> Ended | None:
        """How the current request ended with this answer, or None while it goes on (transfer lock held)."""
        command = data[0]
        request = transfer.request
        if transfer.phase == _Transfer.INITIATE:
            if not names_object(data, request.address):
                if command >> 5 == 2 or command == 0x80:  # an initiate upload answer or abort: names an object
                    transfer.other_object = bytes(data[1:4])
                    self._late_answer(transfer)
                return None
            if command == 0x80:
                return Ended(Outcome.ABORTED, code=int.from_bytes(data[4:8], "little"))
            if command & 0xE3 == 0x43:  # expedited, size indicated
                return Ended(Outcome.VALUE, bytes(data[4:8 - ((command >> 2) & 0x3)]))
            if command & 0xE3 == 0x42:  # expedited, size not indicated
                return Ended(Outcome.VALUE, bytes(data[4:8]))
            if transfer.segmented[transfer.position] and command >> 5 == 2:  # segmented answer
                transfer.size = int.from_bytes(data[4:8], "little") if command & 0x01 else None
                transfer.phase = _Transfer.SEGMENTS
                self._next_segment(transfer)
                return None
            self._abort(request.address, ABORT_INVALID_COMMAND)
            return Ended(Outcome.FOR_THE_BLOCKING_CLIENT)
        if command == 0x80:
            return Ended(Outcome.ABORTED, code=int.from_bytes(data[4:8], "little"))
        if command >> 5 != 0:
            self._abort(request.address, ABORT_INVALID_COMMAND)
            return Ended(Outcome.UNEXPECTED, code=command)
        if (command >> 4) & 1 != transfer.toggle:
            self._abort(request.address, ABORT_TOGGLE)
            return Ended(Outcome.TOGGLE)
        transfer.value += data[1:8 - ((command >> 1) & 0x7)]
        if command & 0x01:  # no more segments
            size = transfer.size
            return Ended(Outcome.VALUE, bytes(transfer.value[:size]) if size is not None else bytes(transfer.value))
        transfer.toggle ^= 1
        self._next_segment(transfer)
        return None

    def _late_answer(self, transfer: _Transfer) -> None:
        """An answer to an earlier request (one sent again after its timeout, answered late) came in while this one
        waits: the node is alive and works through the requests in the order they came, so the answer to this one
        follows. The wait starts again from it (a busy node's late answers do not use up this request's attempts),
        at most :data:`MAX_LATE_ANSWERS` times per request (another client's answers on the same COB-ID)."""
        transfer.stale += 1
        if transfer.stale <= MAX_LATE_ANSWERS:
            transfer.deadline = max(transfer.deadline, time.monotonic() + self._timeout)

    def _next_segment(self, transfer: _Transfer) -> None:
        transfer.frame = bytes([0x60 | transfer.toggle << 4]) + bytes(7)
        self._send(transfer, transfer.frame)

    def _send(self, transfer: _Transfer, frame: bytes) -> None:  # transfer lock held
        transfer.deadline = time.monotonic() + self._timeout
        self.sdo.network.send_message(self.sdo.rx_cobid, frame)

    # --- the event loop ---------------------------------------------------------------------------------------
    def _arm(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        watch = self._watch
        if watch is not None and self._watch_loop is loop and self._watch_at <= deadline:
            return  # fires first, then re-arms for this deadline
        if watch is not None:
            watch.cancel()
        self._watch_after(loop, deadline)

    def _watch_after(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        self._watch = loop.call_later(max(deadline - time.monotonic(), 0.0), self._check, loop)
        self._watch_loop, self._watch_at = loop, deadline

    def _check(self, loop: asyncio.AbstractEventLoop) -> None:
        """The watchdog: an attempt that timed out is sent again right here, under the transfer lock, so an answer
        that comes late is never dropped between the timeout and the next attempt (the transfer takes answers all
        the while); after the last attempt the request ends silent and a batch goes on with the next one."""
        self._watch = None
        transfer = self._transfer
        if transfer is None or self._loop is not loop:
            return
        failed: Exception | None = None
        with transfer.lock:
            if transfer.finished:
                return
            try:
                going_on = transfer.deadline > time.monotonic() or self._next_attempt(transfer)
            except Exception as exc:  # sending failed (the adapter went away): the read fails with it
                going_on, failed = False, exc
            deadline = transfer.deadline
            response = None if going_on else transfer.response
            transfer.finished = not going_on
        if response is None:
            self._watch_after(loop, deadline)
        elif failed is not None:
            response.fail(failed)
        else:
            response.deliver(b"")

    def _next_attempt(self, transfer: _Transfer) -> bool:
        """After a timeout (transfer lock held): send the request again, or end it silent and send the batch's next
        one; False when the transfer is over."""
        progress = transfer.progress()
        transfer.tried = transfer.tried + 1 if progress == transfer.last_progress else 1
        transfer.last_progress = progress
        if transfer.tried < self._attempts:
            self._send(transfer, transfer.frame)
            return True
        self._abort(transfer.request.address, ABORT_TIMEOUT)
        if not transfer.end(transfer.stalled()):
            return False
        transfer.tried, transfer.last_progress = 0, transfer.progress()
        self._send(transfer, transfer.frame)
        return True

    async def _run(self, transfer: _Transfer) -> list[Ended]:
        """Every request of ``transfer`` to its end; each request is sent up to the channel's ``MAX_RETRIES``
        times while it goes unanswered, as canopen's client sends it (the watchdog sends it again)."""
        self._attempts = max(int(self.sdo.MAX_RETRIES), 1)
        self._timeout = float(self.sdo.RESPONSE_TIMEOUT)
        loop = self._loop = asyncio.get_running_loop()
        waker(loop)
        self._transfer = transfer
        try:
            with transfer.lock:
                response = transfer.response = Response(loop)
                transfer.finished = False
                self._send(transfer, transfer.frame)
            self._arm(loop, transfer.deadline)
            await response
            return transfer.ended
        finally:
            with transfer.lock:  # a cancelled read: the reader thread sends nothing more
                transfer.finished = True
            self._transfer = None
            self._drop_client_copies()

    async def upload(self, request: ExpeditedRequest, *, segmented: bool = False, urgent: bool = False
                     ) -> bytes | None:
        """The value, or None when the channel is busy or the device answers other than expedited (``segmented``:
        a segmented answer is read here too, its segments asked for by the bus reader thread). ``urgent`` (a stop's
        read) takes the channel before waiting reads (:class:`~drivebench.protocol.canopen.sdo_queue.ChannelLock`).

        Raises :class:`SdoAbortError` when the device aborts, :class:`SdoTimeoutError` when no attempt is
        answered (the transfer is then aborted with 0x05040000), :class:`SdoStalledError` when the segments stop,
        :class:`SdoOutOfStepError` when the only answers named another object or a segment came out of step."""
        if not self.lock.acquire(blocking=False, urgent=urgent):
            return None
        try:
            ended = await self._run(_Transfer([request], [segmented]))
        finally:
            self.lock.release()
        return self.value(request, ended[0])

    async def upload_many(self, requests: Sequence[ExpeditedRequest], segmented: Sequence[bool]
                          ) -> list[Ended] | None:
        """How each request ended, read one after the other with no event-loop wake-up in between (a batch
        read); None when the channel is busy. :meth:`value` makes each one the value or its error."""
        if not requests:
            return []
        if not self.lock.acquire(blocking=False):
            return None
        try:
            return await self._run(_Transfer(requests, segmented))
        finally:
            self.lock.release()

    def value(self, request: ExpeditedRequest, ended: Ended) -> bytes | None:
        """The value the request read, or None for the blocking client; raises the transfer's error."""
        node, index, subindex = self.node_id, request.index, request.subindex
        match ended.outcome:
            case Outcome.VALUE:
                return ended.data
            case Outcome.FOR_THE_BLOCKING_CLIENT:
                return None
            case Outcome.ABORTED:
                raise SdoAbortError(ended.code, abort_text(ended.code, self.abort_texts), node=node, index=index,
                                    subindex=subindex)
            case Outcome.UNEXPECTED:
                raise SdoOutOfStepError(Text(UNEXPECTED, command=f"0x{ended.code:02X}"), node=node, index=index,
                                        subindex=subindex)
            case Outcome.TOGGLE:
                raise SdoOutOfStepError(SdoOutOfStepError.TOGGLE, node=node, index=index, subindex=subindex)
        if ended.stalled:
            raise SdoStalledError(node=node, index=index, subindex=subindex, done=ended.segments, total=ended.total)
        other = ended.other_object
        if other is not None:  # it did answer, only never for this object
            raise SdoOutOfStepError(SdoOutOfStepError.OTHER_OBJECT, node=node, index=index, subindex=subindex,
                                    answered=(other[0] | other[1] << 8, other[2]))
        silent = Text(SdoTimeoutError.NO_ANSWER, node=node, reason=reason(NO_RESPONSE),
                      object=f"0x{index:04X}sub{subindex}")
        raise SdoTimeoutError(silent, node=node, index=index, subindex=subindex)

    def _drop_client_copies(self) -> None:
        """canopen's client queues a copy of every answer on its COB-ID and empties the queue only at its own next
        transfer: after thousands of reads on this path alone it would hold thousands of stale answers. The
        channel lock is held, so nothing in the queue belongs to a transfer in progress."""
        responses = self.sdo.responses
        if not responses.empty():
            with responses.mutex:
                responses.queue.clear()

    def _abort(self, address: bytes, code: int) -> None:
        self.sdo.network.send_message(self.sdo.rx_cobid, b"\x80" + address + code.to_bytes(4, "little"))


_UPLOADERS: weakref.WeakKeyDictionary[SdoChannel, ExpeditedUploader] = weakref.WeakKeyDictionary()


def uploader(client: NodeClient, channel: int | None = None) -> ExpeditedUploader:
    """The uploader of the node's SDO channel ``channel`` (1-based; None: the first one not busy), made on first
    use and kept as long as the channel."""
    chosen = client.pick_channel(channel)
    found = _UPLOADERS.get(chosen)
    if found is None:
        found = _UPLOADERS[chosen] = ExpeditedUploader(client, chosen)
    return found


async def upload_expedited(client: NodeClient, request: ExpeditedRequest, *, channel: int | None = None,
                           segmented: bool = False, urgent: bool = False) -> bytes | None:
    """The object's value read by an expedited upload on the event loop, or None where the caller must use the
    blocking client (channel busy, segmented answer). Raises the SDO errors of :meth:`ExpeditedUploader.upload`
    and ``ProtocolError`` for a channel number the node has not configured."""
    return await uploader(client, channel).upload(request, segmented=segmented, urgent=urgent)


async def upload_batch(client: NodeClient, requests: Sequence[ExpeditedRequest], segmented: Sequence[bool], *,
                       channel: int | None = None) -> list[bytes | ProtocolError | None] | None:
    """Each object's value (or None where the caller must use the blocking client, or the transfer's error), read
    one after the other on one channel with the next request sent by the bus reader thread as soon as an answer
    ends the one before (no event-loop wake-up in between); None when the channel is busy."""
    chosen = uploader(client, channel)
    ended = await chosen.upload_many(requests, segmented)
    if ended is None:
        return None
    found: list[bytes | ProtocolError | None] = []
    for request, end in zip(requests, ended, strict=True):
        try:
            found.append(chosen.value(request, end))
        except ProtocolError as exc:
            found.append(exc)
    return found
