"""pcapng files with the SocketCAN link type (LINKTYPE_CAN_SOCKETCAN = 227), which Wireshark's CANopen dissector
reads; python-can has no writer for it.

A file is a Section Header Block, one Interface Description Block and an Enhanced Packet Block per frame (all
little-endian, timestamps in microseconds, the default ``if_tsresol``). Each packet is a SocketCAN frame as the
link type specifies: the CAN id with the flags CAN_EFF (bit 31), CAN_RTR (bit 30), CAN_ERR (bit 29) as a
**big-endian** 32-bit word, then payload length, FD flags, two reserved bytes, and the data padded to 8 bytes
(classic CAN, 16 bytes in all) or 64 bytes (CAN FD, 72 bytes: the length tells the two apart).
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import can

LINKTYPE_CAN_SOCKETCAN = 227
CAN_EFF_FLAG = 0x80000000
CAN_RTR_FLAG = 0x40000000
CAN_ERR_FLAG = 0x20000000
CANFD_BRS = 0x01
CANFD_ESI = 0x02
CANFD_FDF = 0x04
CAN_MTU = 16
CANFD_MTU = 72

_SHB = 0x0A0D0D0A
_IDB = 0x00000001
_EPB = 0x00000006
_BYTE_ORDER_MAGIC = 0x1A2B3C4D


def _block(block_type: int, body: bytes) -> bytes:
    padded = body + bytes(-len(body) % 4)
    length = 12 + len(padded)
    return struct.pack("<II", block_type, length) + padded + struct.pack("<I", length)


def section_header() -> bytes:
    # Version 1.0, section length unknown (-1), no options.
    return _block(_SHB, struct.pack("<IHHq", _BYTE_ORDER_MAGIC, 1, 0, -1))


def interface_description(snaplen: int = CANFD_MTU) -> bytes:
    return _block(_IDB, struct.pack("<HHI", LINKTYPE_CAN_SOCKETCAN, 0, snaplen))


def socketcan_frame(msg: can.Message) -> bytes:
    """The frame as the SocketCAN link type carries it (``struct can_frame`` / ``struct canfd_frame``)."""
    can_id = msg.arbitration_id & (0x1FFFFFFF if msg.is_extended_id else 0x7FF)
    if msg.is_extended_id:
        can_id |= CAN_EFF_FLAG
    if msg.is_remote_frame:
        can_id |= CAN_RTR_FLAG
    if msg.is_error_frame:
        can_id = CAN_ERR_FLAG | (msg.arbitration_id & 0x1FFFFFFF)
    data = b"" if msg.is_remote_frame else bytes(msg.data)
    if msg.is_fd:
        flags = CANFD_FDF | (CANFD_BRS if msg.bitrate_switch else 0) | (CANFD_ESI if msg.error_state_indicator else 0)
        return struct.pack(">IBBBB", can_id, len(data), flags, 0, 0) + data[:64].ljust(64, b"\0")
    length = msg.dlc if msg.is_remote_frame else len(data)
    return struct.pack(">IBBBB", can_id, length, 0, 0, 0) + data[:8].ljust(8, b"\0")


def enhanced_packet(msg: can.Message) -> bytes:
    packet = socketcan_frame(msg)
    micros = round(msg.timestamp * 1_000_000)
    header = struct.pack("<IIIII", 0, micros >> 32, micros & 0xFFFFFFFF, len(packet), len(packet))
    return _block(_EPB, header + packet)


class PcapngWriter(can.Listener):
    """A python-can style writer (``on_message_received``/``stop``) for pcapng with LINKTYPE_CAN_SOCKETCAN."""

    def __init__(self, file: str | Path) -> None:
        self.path = Path(file)
        self._file: BinaryIO = self.path.open("wb")
        self._file.write(section_header() + interface_description())
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        block = enhanced_packet(msg)
        with self._lock:
            self._file.write(block)

    def stop(self) -> None:
        with self._lock:
            if not self._file.closed:
                self._file.close()


def read_pcapng(path: str | Path) -> Iterator[can.Message]:
    """The CAN frames of a little-endian pcapng file with SocketCAN interfaces (other packets are skipped)."""
    data = Path(path).read_bytes()
    offset = 0
    linktypes: list[int] = []
    while offset + 12 <= len(data):
        block_type, length = struct.unpack_from("<II", data, offset)
        if length < 12 or offset + length > len(data):
            raise ValueError(f"truncated pcapng block at offset {offset}")
        body = data[offset + 8:offset + length - 4]
        if block_type == _SHB:
            if struct.unpack_from("<I", body)[0] != _BYTE_ORDER_MAGIC:
                raise ValueError("only little-endian pcapng sections are read")
            linktypes = []
        elif block_type == _IDB:
            linktypes.append(struct.unpack_from("<H", body)[0])
        elif block_type == _EPB:
            interface, high, low, captured, _original = struct.unpack_from("<IIIII", body)
            if linktypes[interface] == LINKTYPE_CAN_SOCKETCAN:
                yield _parse_frame(body[20:20 + captured], ((high << 32) | low) / 1_000_000)
        offset += length


def _parse_frame(packet: bytes, timestamp: float) -> can.Message:
    can_id, length, flags = struct.unpack_from(">IBB", packet)
    is_fd = len(packet) == CANFD_MTU
    is_remote = bool(can_id & CAN_RTR_FLAG)
    is_error = bool(can_id & CAN_ERR_FLAG)
    is_extended = bool(can_id & CAN_EFF_FLAG)
    arbitration_id = can_id & (0x1FFFFFFF if is_extended or is_error else 0x7FF)
    return can.Message(timestamp=timestamp, arbitration_id=arbitration_id, is_extended_id=is_extended,
                       is_remote_frame=is_remote, is_error_frame=is_error, is_fd=is_fd,
                       bitrate_switch=bool(flags & CANFD_BRS), error_state_indicator=bool(flags & CANFD_ESI),
                       dlc=length, data=b"" if is_remote else packet[8:8 + length])
