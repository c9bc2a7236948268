"""CoE SDO Information service (ETG.1000.6 5.6.3): a slave describes its object dictionary.

Every SDO Information telegram is CoE service 8 and starts with a 4-byte header: byte 0 the OpCode (bits 0...6) and
the *Incomplete* flag (bit 7: more fragments follow), byte 1 reserved, then *Fragments left* (UINT16). A response
longer than the slave's mailbox comes as several telegrams, counting down Fragments left, without further requests;
the data of the fragments joined is the response (the OD list's List type is only in the first one).

=========================  ======  ============================================================================
Service                    OpCode  Data after the header
=========================  ======  ============================================================================
Get OD List request        1       List type (UINT16)
Get OD List response       2       List type (UINT16), object indices (UINT16 each); list type 0: the lengths of
                                   lists 1...5 (UINT16 each)
Get Object Description     3 / 4   request: Index (UINT16); response: Index, Data type (UINT16), Max subindex
                                   (UINT8), Object code (UINT8: 7 VAR, 8 ARRAY, 9 RECORD), Name (string)
Get Entry Description      5 / 6   request: Index (UINT16), Subindex (UINT8), Value info (UINT8); response: Index,
                                   Subindex, Value info, Data type (UINT16), Bit length (UINT16), Object access
                                   (UINT16), the values the value info asks for, Description (string)
SDO Info Error request     7       Abort code (UINT32)
=========================  ======  ============================================================================
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from drivebench.protocol.ethercat.coe import MailboxFormatError

INFO_HEADER = struct.Struct("<BBH")
INCOMPLETE = 0x80
OBJECT_DESCRIPTION = struct.Struct("<HHBB")
ENTRY_DESCRIPTION = struct.Struct("<HBBHHH")


class InfoOpcode(IntEnum):
    OD_LIST_REQUEST = 1
    OD_LIST_RESPONSE = 2
    OBJECT_DESCRIPTION_REQUEST = 3
    OBJECT_DESCRIPTION_RESPONSE = 4
    ENTRY_DESCRIPTION_REQUEST = 5
    ENTRY_DESCRIPTION_RESPONSE = 6
    ERROR_REQUEST = 7


class ListType(IntEnum):
    LENGTHS = 0
    ALL = 1
    RXPDO_MAPPABLE = 2
    TXPDO_MAPPABLE = 3
    BACKUP = 4
    SETTINGS = 5


class ObjectCode(IntEnum):
    VAR = 7
    ARRAY = 8
    RECORD = 9


class ValueInfo(IntEnum):
    """Bits of the entry description's value info: which values the response carries."""

    UNIT_TYPE = 0x08
    DEFAULT = 0x10
    MINIMUM = 0x20
    MAXIMUM = 0x40


READ_PREOP, READ_SAFEOP, READ_OP = 0x01, 0x02, 0x04
WRITE_PREOP, WRITE_SAFEOP, WRITE_OP = 0x08, 0x10, 0x20
RXPDO_MAPPABLE, TXPDO_MAPPABLE, BACKUP, SETTINGS = 0x40, 0x80, 0x100, 0x200
READ_ALWAYS = READ_PREOP | READ_SAFEOP | READ_OP
WRITE_ALWAYS = WRITE_PREOP | WRITE_SAFEOP | WRITE_OP


@dataclass(frozen=True)
class InfoTelegram:
    opcode: int
    incomplete: bool
    fragments_left: int
    data: bytes


def info_body(opcode: int, data: bytes, *, incomplete: bool = False, fragments_left: int = 0) -> bytes:
    return INFO_HEADER.pack((opcode & 0x7F) | (INCOMPLETE if incomplete else 0), 0, fragments_left) + data


def parse_info(body: bytes) -> InfoTelegram:
    if len(body) < INFO_HEADER.size:
        raise MailboxFormatError(f"an SDO information telegram needs its 4-byte header, it has {len(body)} bytes")
    opcode, _reserved, left = INFO_HEADER.unpack_from(body)
    return InfoTelegram(opcode & 0x7F, bool(opcode & INCOMPLETE), left, bytes(body[INFO_HEADER.size:]))


def fragments(opcode: int, data: bytes, room: int) -> list[bytes]:
    """A response as the telegram bodies that carry it, ``room`` data bytes each (the last one complete)."""
    if room < 2:
        raise ValueError(f"{room} bytes per fragment cannot carry an SDO information response")
    chunks = [data[start:start + room] for start in range(0, len(data), room)] or [b""]
    return [info_body(opcode, chunk, incomplete=number < len(chunks) - 1, fragments_left=len(chunks) - 1 - number)
            for number, chunk in enumerate(chunks)]


# --- requests ------------------------------------------------------------------------------------------------
def od_list_request(list_type: int) -> bytes:
    return info_body(InfoOpcode.OD_LIST_REQUEST, struct.pack("<H", list_type))


def object_description_request(index: int) -> bytes:
    return info_body(InfoOpcode.OBJECT_DESCRIPTION_REQUEST, struct.pack("<H", index))


def entry_description_request(index: int, subindex: int, value_info: int = 0) -> bytes:
    return info_body(InfoOpcode.ENTRY_DESCRIPTION_REQUEST, struct.pack("<HBB", index, subindex, value_info))


def info_error(code: int) -> bytes:
    return info_body(InfoOpcode.ERROR_REQUEST, struct.pack("<I", code))


def request_key(body: bytes) -> tuple[int, int]:
    """The object (index, subindex) a request asks about, (0, 0) for the OD list: for error texts."""
    info = parse_info(body)
    index = int.from_bytes(info.data[:2], "little") if info.opcode != InfoOpcode.OD_LIST_REQUEST else 0
    subindex = info.data[2] if info.opcode == InfoOpcode.ENTRY_DESCRIPTION_REQUEST and len(info.data) > 2 else 0
    return index, subindex


# --- responses -----------------------------------------------------------------------------------------------
def od_list_data(list_type: int, indices: list[int]) -> bytes:
    return struct.pack(f"<H{len(indices)}H", list_type, *indices)


def parse_od_list(data: bytes) -> tuple[int, list[int]]:
    if len(data) < 2 or len(data) % 2:
        raise MailboxFormatError(f"an OD list of {len(data)} bytes is not a list type and UINT16 indices")
    words = struct.unpack(f"<{len(data) // 2}H", data)
    return words[0], list(words[1:])


@dataclass(frozen=True)
class ObjectDescription:
    index: int
    data_type: int
    max_subindex: int
    object_code: int
    name: str

    def encode(self) -> bytes:
        return OBJECT_DESCRIPTION.pack(self.index, self.data_type, self.max_subindex, self.object_code) + \
            self.name.encode("latin-1", "replace")

    @classmethod
    def decode(cls, data: bytes) -> ObjectDescription:
        if len(data) < OBJECT_DESCRIPTION.size:
            raise MailboxFormatError(f"an object description needs 6 bytes before its name, it has {len(data)}")
        index, data_type, max_subindex, object_code = OBJECT_DESCRIPTION.unpack_from(data)
        name = data[OBJECT_DESCRIPTION.size:].decode("latin-1").rstrip("\0")
        return cls(index, data_type, max_subindex, object_code, name)

    @property
    def object_code_text(self) -> str:
        try:
            return ObjectCode(self.object_code).name
        except ValueError:
            return f"object code {self.object_code}"


@dataclass(frozen=True)
class EntryDescription:
    index: int
    subindex: int
    data_type: int
    bit_length: int
    access: int
    name: str
    value_info: int = 0
    values: bytes = b""
    """Unit type, default, minimum and maximum, those the value info names, in this order."""

    def encode(self) -> bytes:
        return ENTRY_DESCRIPTION.pack(self.index, self.subindex, self.value_info, self.data_type, self.bit_length,
                                      self.access) + self.values + self.name.encode("latin-1", "replace")

    @classmethod
    def decode(cls, data: bytes) -> EntryDescription:
        if len(data) < ENTRY_DESCRIPTION.size:
            raise MailboxFormatError(f"an entry description needs 10 bytes before its values, it has {len(data)}")
        index, subindex, value_info, data_type, bit_length, access = ENTRY_DESCRIPTION.unpack_from(data)
        value_bytes = -(-bit_length // 8)
        size = (4 if value_info & ValueInfo.UNIT_TYPE else 0) + value_bytes * sum(
            1 for flag in (ValueInfo.DEFAULT, ValueInfo.MINIMUM, ValueInfo.MAXIMUM) if value_info & flag)
        rest = data[ENTRY_DESCRIPTION.size:]
        return cls(index, subindex, data_type, bit_length, access, rest[size:].decode("latin-1").rstrip("\0"),
                   value_info, bytes(rest[:size]))
