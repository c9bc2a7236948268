"""CANopen over EtherCAT (CoE, ETG.1000.6) mailbox telegrams and the ETG.8200 mailbox-gateway frame around them.

A mailbox telegram is a 6-byte mailbox header (length of what follows, station address, channel/priority,
type/counter) and the service data. For CoE the service data starts with a 2-byte CoE header (number, service);
SDO services then carry the CiA 301 command byte, index, subindex and a DWORD, as the 8400 motec EtherCAT manual
prints them (chapter 9.2: "Mailbox header 6 bytes | CoE header 2 bytes | SDO control byte | Index | Subindex |
Data 4 bytes | Data 1 … n bytes"). How telegrams travel (a mailbox gateway over UDP, a master on a NIC) is the
transport's (:mod:`drivebench.transport.ethercat_gateway`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

MAILBOX_HEADER = struct.Struct("<HHBB")
SDO_FRAME = struct.Struct("<BHBI")
"""command byte, index, subindex, DWORD (data, complete size, abort code or reserved)."""
SDO_MIN_LENGTH = 2 + SDO_FRAME.size  # CoE header + the SDO frame: the mailbox length 0x0A of the manual's tables


class MailboxType(IntEnum):
    ERROR = 0
    AOE = 1
    EOE = 2
    COE = 3
    FOE = 4
    SOE = 5
    VOE = 15


class CoeService(IntEnum):
    EMERGENCY = 1
    SDO_REQUEST = 2
    SDO_RESPONSE = 3
    TXPDO = 4
    RXPDO = 5
    TXPDO_REMOTE_REQUEST = 6
    RXPDO_REMOTE_REQUEST = 7
    SDO_INFORMATION = 8


class MailboxFormatError(ValueError):
    """Bytes that are not a well-formed telegram; the text says what is wrong."""


@dataclass(frozen=True)
class Mailbox:
    address: int
    """Station address: of the target slave in a request, of the answering slave in a response."""
    type: int
    data: bytes
    counter: int = 0
    """1…7, repeated unchanged when a request is sent again (0: the sender counts nothing)."""
    channel: int = 0
    priority: int = 0

    def encode(self) -> bytes:
        return MAILBOX_HEADER.pack(len(self.data), self.address, (self.channel & 0x3F) | (self.priority & 3) << 6,
                                   (self.type & 0x0F) | (self.counter & 7) << 4) + self.data

    @classmethod
    def decode(cls, raw: bytes) -> Mailbox:
        if len(raw) < MAILBOX_HEADER.size:
            raise MailboxFormatError(f"{len(raw)} bytes are too short for a mailbox header (6 bytes)")
        length, address, channel_priority, type_counter = MAILBOX_HEADER.unpack_from(raw)
        if MAILBOX_HEADER.size + length > len(raw):
            raise MailboxFormatError(f"the mailbox header says {length} bytes follow, {len(raw) - 6} do")
        return cls(address=address, type=type_counter & 0x0F, counter=(type_counter >> 4) & 7,
                   channel=channel_priority & 0x3F, priority=channel_priority >> 6,
                   data=bytes(raw[MAILBOX_HEADER.size:MAILBOX_HEADER.size + length]))


@dataclass(frozen=True)
class CoeMessage:
    service: int
    body: bytes
    number: int = 0
    """PDO number for PDO services; 0 for SDO and emergency."""

    def encode(self) -> bytes:
        return struct.pack("<H", (self.number & 0x1FF) | (self.service & 0x0F) << 12) + self.body

    @classmethod
    def decode(cls, data: bytes) -> CoeMessage:
        if len(data) < 2:
            raise MailboxFormatError("a CoE telegram needs its 2-byte CoE header")
        (header,) = struct.unpack_from("<H", data)
        return cls(service=header >> 12, number=header & 0x1FF, body=bytes(data[2:]))


def coe_mailbox(address: int, service: CoeService, body: bytes, counter: int = 0) -> bytes:
    """A whole CoE telegram: mailbox header, CoE header, ``body``."""
    return Mailbox(address, MailboxType.COE, CoeMessage(service, body).encode(), counter).encode()


# --- SDO telegrams -------------------------------------------------------------------------------------------------
# Command bytes are CiA 301's (client: 1 download initiate, 2 upload initiate, 0 download segment, 3 upload segment,
# 4 abort; server: 3 download initiate, 2 upload initiate, 1 download segment, 0 upload segment).
SIZE_INDICATED, EXPEDITED = 0x01, 0x02
ABORT = 0x80


def _expedited_bits(size: int) -> int:
    return EXPEDITED | SIZE_INDICATED | (4 - size) << 2


def sdo_frame(command: int, index: int, subindex: int, dword: int = 0, tail: bytes = b"") -> bytes:
    """CoE SDO body: command byte, index, subindex, DWORD, then the data of a normal transfer."""
    return SDO_FRAME.pack(command, index, subindex, dword) + tail


def upload_request(index: int, subindex: int) -> bytes:
    return sdo_frame(0x40, index, subindex)


def upload_response(index: int, subindex: int, data: bytes, room: int) -> bytes:
    """Expedited for 1…4 bytes, else normal with the complete size (0 for an empty object: expedited cannot say
    0 bytes) and as much data as ``room`` allows."""
    if 1 <= len(data) <= 4:
        return sdo_frame(0x40 | _expedited_bits(len(data)), index, subindex,
                         int.from_bytes(data.ljust(4, b"\0"), "little"))
    return sdo_frame(0x40 | SIZE_INDICATED, index, subindex, len(data), data[:room])


def download_request(index: int, subindex: int, data: bytes, room: int) -> bytes:
    """Expedited for 1…4 bytes, else normal: the complete size and the first ``room`` bytes (the rest follows in
    download segments)."""
    if 1 <= len(data) <= 4:
        return sdo_frame(0x20 | _expedited_bits(len(data)), index, subindex,
                         int.from_bytes(data.ljust(4, b"\0"), "little"))
    return sdo_frame(0x20 | SIZE_INDICATED, index, subindex, len(data), data[:room])


def download_response(index: int, subindex: int) -> bytes:
    return sdo_frame(0x60, index, subindex)


def abort(index: int, subindex: int, code: int) -> bytes:
    return sdo_frame(ABORT, index, subindex, code)


def segment(command: int, toggle: int, data: bytes, last: bool) -> bytes:
    """A download segment (command 0x00) or upload segment response (0x00 as well, from the server) or request
    (0x60): the command byte, then data. Fewer than 7 data bytes are padded to 7 and the unused count is said in
    bits 1…3, as on CAN; a longer segment fills the mailbox and its length says how much it carries."""
    unused = 7 - len(data) if len(data) < 7 else 0
    return bytes([command | (toggle & 1) << 4 | unused << 1 | int(last)]) + data.ljust(7, b"\0")


@dataclass(frozen=True)
class SdoTelegram:
    """An SDO body read back: what a client or server needs to go on."""

    command: int
    index: int
    subindex: int
    dword: int
    tail: bytes

    @property
    def specifier(self) -> int:
        return self.command >> 5

    @property
    def is_abort(self) -> bool:
        return self.command == ABORT

    @property
    def expedited_data(self) -> bytes:
        size = 4 - (self.command >> 2 & 3) if self.command & SIZE_INDICATED else 4
        return self.dword.to_bytes(4, "little")[:size]

    @property
    def expedited(self) -> bool:
        return bool(self.command & EXPEDITED)


def parse_sdo(body: bytes) -> SdoTelegram:
    if len(body) < SDO_FRAME.size:
        raise MailboxFormatError(f"an SDO telegram needs 8 bytes after the CoE header, it has {len(body)}")
    command, index, subindex, dword = SDO_FRAME.unpack_from(body)
    return SdoTelegram(command, index, subindex, dword, bytes(body[SDO_FRAME.size:]))


@dataclass(frozen=True)
class Segment:
    toggle: int
    last: bool
    data: bytes
    specifier: int


def parse_segment(body: bytes) -> Segment:
    """An SDO segment (download segment request, upload segment response, or their answers)."""
    if not body:
        raise MailboxFormatError("an SDO segment needs its command byte")
    command = body[0]
    payload = body[1:]
    if len(payload) <= 7:
        payload = payload[:7 - (command >> 1 & 7)]
    return Segment(toggle=command >> 4 & 1, last=bool(command & 1), data=bytes(payload), specifier=command >> 5)


# --- emergency --------------------------------------------------------------------------------------------------
EMERGENCY = struct.Struct("<HB5s")


def emergency(code: int, register: int, data: bytes = b"") -> bytes:
    """CoE emergency body: the 8 bytes of a CiA 301 EMCY (error code, error register, 5 bytes)."""
    return EMERGENCY.pack(code, register, data.ljust(5, b"\0")[:5])


def parse_emergency(body: bytes) -> tuple[int, int, bytes]:
    if len(body) < EMERGENCY.size:
        raise MailboxFormatError(f"a CoE emergency has 8 bytes, this one {len(body)}")
    code, register, data = EMERGENCY.unpack_from(body)
    return code, register, data
