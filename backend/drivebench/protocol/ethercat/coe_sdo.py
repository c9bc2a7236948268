"""SDO client over an EtherCAT mailbox (CoE): expedited, normal and segmented upload and download, with the same
errors as CAN SDO (abort in words, timeout, stalled segmented transfer, answer out of step).

The mailbox itself is reached through ``exchange(telegram, timeout_s)``: it sends one mailbox telegram and returns
the slave's answering telegram, or ``None`` when none came in time (a mailbox gateway over UDP, a pysoem master,
or a test). A request that got no answer is sent again with the same mailbox counter, so a slave that did receive
it can tell the repetition from a new request. One transfer at a time per slave: the caller holds its lock.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

from drivebench.errors import ProtocolError, SdoAbortError, SdoOutOfStepError, SdoStalledError, SdoTimeoutError
from drivebench.i18n import N_, Text
from drivebench.protocol.abort_codes import abort_text
from drivebench.protocol.ethercat import coe, coe_info

Exchange = Callable[[bytes, float], bytes | None]
Receive = Callable[[float], bytes | None]
"""The slave's next telegram without sending one (the further fragments of an SDO information response)."""
DEFAULT_MAILBOX_SIZE = 128
"""Bytes of the slave's mailbox (SyncManager 0/1 length): the 8400 motec EtherCAT unit has 128."""

MAILBOX_ERRORS = {
    0x01: N_("syntax error in the mailbox header"), 0x02: N_("the protocol is not supported"),
    0x03: N_("invalid channel"), 0x04: N_("the service is not supported"), 0x05: N_("invalid mailbox header"),
    0x06: N_("the mailbox data is too short"), 0x07: N_("the slave has no memory left for the mailbox"),
    0x08: N_("invalid data size"),
}
"""ETG.1000.6 mailbox error replies (mailbox type 0)."""
SERVICE_NOT_SUPPORTED = 0x04


class MailboxRefused(ProtocolError):
    """The slave answered with a mailbox error (type 0); ``code`` is its detail (:data:`MAILBOX_ERRORS`)."""

    def __init__(self, detail: str, code: int) -> None:
        super().__init__(detail)
        self.code = code


class CoeSdoClient:
    def __init__(self, exchange: Exchange, station: int, *, mailbox_size: int = DEFAULT_MAILBOX_SIZE,
                 timeout_s: float = 0.5, retries: int = 1, receive: Receive | None = None) -> None:
        if mailbox_size < coe.MAILBOX_HEADER.size + coe.SDO_MIN_LENGTH:
            raise ValueError(f"a mailbox of {mailbox_size} bytes cannot hold an SDO telegram")
        self.exchange = exchange
        self.receive = receive
        self.station = station
        self.mailbox_size = mailbox_size
        self.timeout_s = timeout_s
        self.retries = retries
        self._counters = itertools.cycle(range(1, 8))

    # --- one request, one answer ----------------------------------------------------------------------------
    def _send(self, service: coe.CoeService, body: bytes, what: str, index: int, subindex: int) -> bytes:
        telegram = coe.coe_mailbox(self.station, service, body, next(self._counters))
        for _ in range(self.retries + 1):
            answer = self.exchange(telegram, self.timeout_s)
            if answer is not None:
                return answer
        raise SdoTimeoutError(Text(N_("Slave {station} did not answer the {what} for {object} within {seconds} s "
                                       "({tries} tries)"), station=self.station, what=what, tries=self.retries + 1,
                                    seconds=f"{self.timeout_s:g}", object=f"0x{index:04X}sub{subindex}"),
                              node=self.station, index=index, subindex=subindex)

    def _ask(self, body: bytes, index: int, subindex: int) -> bytes:
        answer = self._send(coe.CoeService.SDO_REQUEST, body, Text(N_("SDO request")), index, subindex)
        return self._sdo_body(answer, index, subindex)

    def _coe_message(self, answer: bytes, index: int, subindex: int) -> coe.CoeMessage:
        try:
            mailbox = coe.Mailbox.decode(answer)
            if mailbox.type == coe.MailboxType.ERROR:
                detail = int.from_bytes(mailbox.data[2:4], "little") if len(mailbox.data) >= 4 else 0
                reason = Text(MAILBOX_ERRORS.get(detail, N_("mailbox error {code}")), code=f"0x{detail:04X}")
                raise MailboxRefused(Text(N_("Slave {station} refused the mailbox request for {object}: {reason}"),
                                           station=self.station, object=f"0x{index:04X}sub{subindex}", reason=reason),
                                     detail)
            if mailbox.type != coe.MailboxType.COE:
                raise SdoOutOfStepError(Text(N_("a mailbox of type {type} answered a CoE request"),
                                              type=mailbox.type), node=self.station, index=index, subindex=subindex)
            return coe.CoeMessage.decode(mailbox.data)
        except coe.MailboxFormatError as exc:
            raise ProtocolError(Text(N_("Slave {station}: malformed answer for {object}: {reason}"),
                                      station=self.station, object=f"0x{index:04X}sub{subindex}", reason=exc)) \
                from exc

    def _sdo_body(self, answer: bytes, index: int, subindex: int) -> bytes:
        message = self._coe_message(answer, index, subindex)
        if message.service not in (coe.CoeService.SDO_RESPONSE, coe.CoeService.SDO_REQUEST):
            raise SdoOutOfStepError(Text(N_("CoE service {service} answered an SDO request"), service=message.service),
                                    node=self.station, index=index, subindex=subindex)
        if len(message.body) >= coe.SDO_FRAME.size and message.body[0] == coe.ABORT:
            frame = coe.parse_sdo(message.body)
            raise SdoAbortError(frame.dword, abort_text(frame.dword), node=self.station, index=index,
                                subindex=subindex)
        return message.body

    def _initiate(self, body: bytes, index: int, subindex: int, specifier: int) -> coe.SdoTelegram:
        frame = coe.parse_sdo(self._ask(body, index, subindex))
        if frame.specifier != specifier:
            raise SdoOutOfStepError(Text(N_("command {command}"), command=f"0x{frame.command:02X}"),
                                    node=self.station, index=index, subindex=subindex)
        if (frame.index, frame.subindex) != (index, subindex):
            raise SdoOutOfStepError(SdoOutOfStepError.OTHER_OBJECT, node=self.station, index=index, subindex=subindex,
                                    answered=(frame.index, frame.subindex))
        return frame

    # --- transfers -----------------------------------------------------------------------------------------
    @property
    def _initiate_room(self) -> int:
        return self.mailbox_size - coe.MAILBOX_HEADER.size - coe.SDO_MIN_LENGTH

    @property
    def _segment_room(self) -> int:
        return self.mailbox_size - coe.MAILBOX_HEADER.size - 3  # CoE header and the segment's command byte

    def _segments_for(self, left: int) -> int:
        """How many segments carry the ``left`` bytes that the initiate telegram did not."""
        return -(-left // self._segment_room) if left > 0 else 0

    def _segment_exchange(self, request: bytes, index: int, subindex: int, *, specifier: int, toggle: int, done: int,
                          total: int, wrong_specifier: str) -> coe.Segment:
        """One segment of an upload or download: ``request`` sent and its answer checked. No answer stalls the
        transfer after ``done`` of ``total`` segments; an answer with another command specifier (said by the
        N_() template ``wrong_specifier``) or toggle bit is out of step."""
        try:
            answer = coe.parse_segment(self._ask(request, index, subindex))
        except SdoTimeoutError as exc:
            raise SdoStalledError(node=self.station, index=index, subindex=subindex, done=done, total=total) from exc
        if answer.specifier != specifier:
            raise SdoOutOfStepError(Text(wrong_specifier, specifier=answer.specifier),
                                    node=self.station, index=index, subindex=subindex)
        if answer.toggle != toggle:
            raise SdoOutOfStepError(SdoOutOfStepError.TOGGLE, node=self.station, index=index, subindex=subindex)
        return answer

    def upload(self, index: int, subindex: int) -> bytes:
        frame = self._initiate(coe.upload_request(index, subindex), index, subindex, specifier=2)
        if frame.expedited:
            return frame.expedited_data
        size = frame.dword
        data = bytearray(frame.tail[:size])
        toggle, done = 0, 0
        total = self._segments_for(size - len(data))
        while len(data) < size:
            segment = self._segment_exchange(bytes([0x60 | toggle << 4]) + bytes(7), index, subindex,
                                             specifier=0, toggle=toggle, done=done, total=total,
                                             wrong_specifier=N_("command specifier {specifier} in an upload segment"))
            data += segment.data
            done += 1
            toggle ^= 1
            if segment.last:
                break
        return bytes(data[:size])

    def download(self, index: int, subindex: int, data: bytes) -> None:
        self._initiate(coe.download_request(index, subindex, data, self._initiate_room), index, subindex,
                       specifier=3)
        if 1 <= len(data) <= 4:
            return
        sent = min(len(data), self._initiate_room)
        toggle, done = 0, 0
        total = self._segments_for(len(data) - sent)
        while sent < len(data):
            chunk = data[sent:sent + self._segment_room]
            last = sent + len(chunk) == len(data)
            self._segment_exchange(coe.segment(0x00, toggle, chunk, last), index, subindex,
                                   specifier=1, toggle=toggle, done=done, total=total,
                                   wrong_specifier=N_("command specifier {specifier} answering a download segment"))
            sent += len(chunk)
            done += 1
            toggle ^= 1

    # --- SDO information service (ETG.1000.6 5.6.3) ----------------------------------------------------------
    def information(self, request: bytes) -> bytes:
        """Send an SDO information request and return its response's data, the fragments joined. A slave without
        the service answers with a mailbox error (in words), an SDO Info Error request raises its abort code."""
        index, subindex = coe_info.request_key(request)
        expected = coe_info.parse_info(request).opcode + 1
        answer: bytes | None = self._send(coe.CoeService.SDO_INFORMATION, request,
                                          Text(N_("SDO information request")), index, subindex)
        data, fragment, left = bytearray(), 0, None
        while True:
            assert answer is not None
            message = self._coe_message(answer, index, subindex)
            if message.service != coe.CoeService.SDO_INFORMATION:
                raise SdoOutOfStepError(Text(N_("CoE service {service} answered an SDO information request"),
                                              service=message.service),
                                        node=self.station, index=index, subindex=subindex)
            try:
                info = coe_info.parse_info(message.body)
            except coe.MailboxFormatError as exc:
                raise ProtocolError(Text(N_("Slave {station}: malformed SDO information answer: {reason}"),
                                          station=self.station, reason=exc)) from exc
            if info.opcode == coe_info.InfoOpcode.ERROR_REQUEST:
                code = int.from_bytes(info.data[:4], "little")
                raise SdoAbortError(code, abort_text(code), node=self.station, index=index, subindex=subindex)
            if info.opcode != expected:
                raise SdoOutOfStepError(Text(N_("SDO information opcode {opcode} answered opcode {asked}"),
                                              opcode=info.opcode, asked=expected - 1),
                                        node=self.station, index=index, subindex=subindex)
            if left is not None and info.fragments_left != left - 1:
                raise SdoOutOfStepError(Text(N_("a fragment of the SDO information response was lost ({expected} "
                                                 "fragments left expected, the slave says {left})"),
                                              expected=left - 1, left=info.fragments_left),
                                        node=self.station, index=index, subindex=subindex)
            data += info.data
            if not info.incomplete:
                return bytes(data)
            left, fragment = info.fragments_left, fragment + 1
            answer = self.receive(self.timeout_s) if self.receive is not None else None
            if answer is None:
                raise SdoStalledError(node=self.station, index=index, subindex=subindex, done=fragment,
                                      total=fragment + left, what=Text(N_("the SDO information response")),
                                      kind="fragmented")

    def od_list(self, list_type: int = coe_info.ListType.ALL) -> list[int]:
        answered, indices = coe_info.parse_od_list(self.information(coe_info.od_list_request(list_type)))
        if answered != list_type:
            raise SdoOutOfStepError(Text(N_("OD list type {answered} answered a request for type {asked}"),
                                          answered=answered, asked=list_type),
                                    node=self.station, index=0, subindex=0)
        return indices

    def object_description(self, index: int) -> coe_info.ObjectDescription:
        return coe_info.ObjectDescription.decode(self.information(coe_info.object_description_request(index)))

    def entry_description(self, index: int, subindex: int, value_info: int = 0) -> coe_info.EntryDescription:
        return coe_info.EntryDescription.decode(
            self.information(coe_info.entry_description_request(index, subindex, value_info)))
