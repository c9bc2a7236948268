"""SDO server of a (simulated) EtherCAT slave: answers CoE SDO requests against the slave's objects.

``read(index, subindex) -> bytes`` and ``write(index, subindex, data)`` are the slave's object dictionary; they raise
:class:`Abort` with a CiA 301 / ETG abort code. Answers are whole mailbox telegrams. A request repeated with the
same non-zero mailbox counter (the client's retry after a lost answer) gets the previous answer again instead of
being carried out twice. With an :class:`ObjectDictionary` it also answers the SDO information service
(:mod:`drivebench.protocol.ethercat.coe_info`), in as many fragments as its mailbox needs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from drivebench.protocol.ethercat import coe, coe_info

ABORT_TOGGLE = 0x05030000
ABORT_COMMAND = 0x05040001
ABORT_NO_OBJECT = 0x06020000
ABORT_GENERAL = 0x08000000
MAILBOX_SERVICE_NOT_SUPPORTED = 0x04


class ObjectDictionary(Protocol):
    """What a slave says about its objects through the SDO information service; raises :class:`Abort`."""

    def od_list(self, list_type: int) -> list[int]: ...

    def object_description(self, index: int) -> coe_info.ObjectDescription: ...

    def entry_description(self, index: int, subindex: int, value_info: int = 0) -> coe_info.EntryDescription:
        """``value_info``: the values asked for (the answer's value info says which it carries)."""
        ...


class Abort(Exception):
    """An SDO abort the slave answers with ``code``."""

    def __init__(self, code: int) -> None:
        super().__init__(f"SDO abort 0x{code:08X}")
        self.code = code


@dataclass
class _Upload:
    index: int
    subindex: int
    data: bytes
    sent: int
    toggle: int = 0


@dataclass
class _Download:
    index: int
    subindex: int
    size: int
    data: bytearray
    toggle: int = 0


class CoeSdoServer:
    def __init__(self, station: int, read: Callable[[int, int], bytes], write: Callable[[int, int, bytes], None],
                 *, mailbox_size: int = 128, dictionary: ObjectDictionary | None = None) -> None:
        self.station = station
        self.read = read
        self.write = write
        self.mailbox_size = mailbox_size
        self.dictionary = dictionary
        """Answers the SDO information service; None: the slave does not offer it (mailbox error)."""
        self._upload: _Upload | None = None
        self._download: _Download | None = None
        self._last: tuple[int, bytes, list[bytes]] | None = None  # counter, request, answers
        self._counters = 0

    def _answer(self, service: coe.CoeService, body: bytes) -> bytes:
        self._counters = self._counters % 7 + 1
        return coe.coe_mailbox(self.station, service, body, self._counters)

    def _abort(self, index: int, subindex: int, code: int) -> bytes:
        """An SDO abort of the transfer of ``index``/``subindex`` (CoE carries an abort in the SDO request service)."""
        return self._answer(coe.CoeService.SDO_REQUEST, coe.abort(index, subindex, code))

    def handle(self, telegram: bytes) -> bytes | None:
        """The (first) answer to one request telegram, or None for telegrams a slave ignores."""
        answers = self.respond(telegram)
        return answers[0] if answers else None

    def respond(self, telegram: bytes) -> list[bytes]:
        """The answers to one request telegram (several: the fragments of an SDO information response)."""
        try:
            mailbox = coe.Mailbox.decode(telegram)
        except coe.MailboxFormatError:
            return []
        if self._last and mailbox.counter and self._last[0] == mailbox.counter and self._last[1] == telegram:
            return self._last[2]
        if mailbox.type != coe.MailboxType.COE:
            return []
        message = coe.CoeMessage.decode(mailbox.data)
        if message.service == coe.CoeService.SDO_INFORMATION:
            answers = self._information(message.body)
        elif message.service == coe.CoeService.SDO_REQUEST and message.body:
            answer = self._sdo(message.body)
            answers = [answer] if answer is not None else []
        else:
            return []
        if answers:
            self._last = (mailbox.counter, telegram, answers)
        return answers

    # --- SDO information service -------------------------------------------------------------------------
    def _information(self, body: bytes) -> list[bytes]:
        if self.dictionary is None:  # ETG.1000.6 mailbox error reply: command 0x01, detail "service not supported"
            self._counters = self._counters % 7 + 1
            return [coe.Mailbox(self.station, coe.MailboxType.ERROR, bytes([1, 0, MAILBOX_SERVICE_NOT_SUPPORTED, 0]),
                                self._counters).encode()]
        try:
            info = coe_info.parse_info(body)
            opcode, data = self._describe(info)
        except Abort as exc:
            return [self._answer(coe.CoeService.SDO_INFORMATION, coe_info.info_error(exc.code))]
        except (coe.MailboxFormatError, IndexError, ValueError):
            return [self._answer(coe.CoeService.SDO_INFORMATION, coe_info.info_error(ABORT_COMMAND))]
        room = self.mailbox_size - coe.MAILBOX_HEADER.size - 2 - coe_info.INFO_HEADER.size
        return [self._answer(coe.CoeService.SDO_INFORMATION, fragment)
                for fragment in coe_info.fragments(opcode, data, room)]

    def _describe(self, info: coe_info.InfoTelegram) -> tuple[int, bytes]:
        assert self.dictionary is not None
        op = coe_info.InfoOpcode
        if info.opcode == op.OD_LIST_REQUEST and len(info.data) >= 2:
            list_type = int.from_bytes(info.data[:2], "little")
            if list_type == coe_info.ListType.LENGTHS:
                lengths = [len(self.dictionary.od_list(kind)) for kind in range(1, 6)]
                return op.OD_LIST_RESPONSE, coe_info.od_list_data(list_type, lengths)
            return op.OD_LIST_RESPONSE, coe_info.od_list_data(list_type, self.dictionary.od_list(list_type))
        if info.opcode == op.OBJECT_DESCRIPTION_REQUEST and len(info.data) >= 2:
            index = int.from_bytes(info.data[:2], "little")
            return op.OBJECT_DESCRIPTION_RESPONSE, self.dictionary.object_description(index).encode()
        if info.opcode == op.ENTRY_DESCRIPTION_REQUEST and len(info.data) >= 4:
            index = int.from_bytes(info.data[:2], "little")
            described = self.dictionary.entry_description(index, info.data[2], info.data[3])
            return op.ENTRY_DESCRIPTION_RESPONSE, described.encode()
        raise Abort(ABORT_COMMAND)

    def _sdo(self, body: bytes) -> bytes | None:
        specifier = body[0] >> 5
        if specifier in (0, 3):  # download segment / upload segment: no index in the telegram
            return self._segment(specifier, body)
        frame = coe.parse_sdo(body)
        self._upload = self._download = None
        try:
            if frame.is_abort:  # the client gave up the transfer: nothing to answer
                return None
            if specifier == 2:
                return self._initiate_upload(frame)
            if specifier == 1:
                return self._initiate_download(frame)
            raise Abort(ABORT_COMMAND)
        except Abort as exc:
            return self._abort(frame.index, frame.subindex, exc.code)

    @property
    def _initiate_room(self) -> int:
        return self.mailbox_size - coe.MAILBOX_HEADER.size - coe.SDO_MIN_LENGTH

    @property
    def _segment_room(self) -> int:
        return self.mailbox_size - coe.MAILBOX_HEADER.size - 3

    def _initiate_upload(self, frame: coe.SdoTelegram) -> bytes:
        data = self.read(frame.index, frame.subindex)
        body = coe.upload_response(frame.index, frame.subindex, data, self._initiate_room)
        if len(data) > 4 and len(data) > self._initiate_room:
            self._upload = _Upload(frame.index, frame.subindex, data, self._initiate_room)
        return self._answer(coe.CoeService.SDO_RESPONSE, body)

    def _initiate_download(self, frame: coe.SdoTelegram) -> bytes:
        if frame.expedited:
            self.write(frame.index, frame.subindex, frame.expedited_data)
        else:
            data = frame.tail[:frame.dword]
            if len(data) < frame.dword:
                self._download = _Download(frame.index, frame.subindex, frame.dword, bytearray(data))
                return self._answer(coe.CoeService.SDO_RESPONSE, coe.download_response(frame.index, frame.subindex))
            self.write(frame.index, frame.subindex, bytes(data))
        return self._answer(coe.CoeService.SDO_RESPONSE, coe.download_response(frame.index, frame.subindex))

    def _segment(self, specifier: int, body: bytes) -> bytes:
        segment = coe.parse_segment(body)
        if specifier == 3 and self._upload is not None:
            upload = self._upload
            if segment.toggle != upload.toggle:
                self._upload = None
                return self._abort(upload.index, upload.subindex, ABORT_TOGGLE)
            chunk = upload.data[upload.sent:upload.sent + self._segment_room]
            upload.sent += len(chunk)
            last = upload.sent >= len(upload.data)
            answer = coe.segment(0x00, upload.toggle, chunk, last)
            upload.toggle ^= 1
            if last:
                self._upload = None
            return self._answer(coe.CoeService.SDO_RESPONSE, answer)
        if specifier == 0 and self._download is not None:
            download = self._download
            if segment.toggle != download.toggle:
                self._download = None
                return self._abort(download.index, download.subindex, ABORT_TOGGLE)
            download.data += segment.data
            answer = bytes([0x20 | download.toggle << 4]) + bytes(7)
            download.toggle ^= 1
            if segment.last or len(download.data) >= download.size:
                self._download = None
                try:
                    self.write(download.index, download.subindex, bytes(download.data[:download.size]))
                except Abort as exc:
                    return self._abort(download.index, download.subindex, exc.code)
            return self._answer(coe.CoeService.SDO_RESPONSE, answer)
        return self._abort(0, 0, ABORT_COMMAND)
