"""Decode one CAN frame as CANopen (CiA 301 predefined connection set): service, node and a text in words.

``decode_frame`` is stateless. SDO segments and block transfers are only meaningful with what went before (a
block download's data segments on 0x600+n look like other commands), so ``SdoTracker`` follows each node's SDO
channel and hands the decoder an ``SdoContext``: the object being transferred and whether the frame is a block
data segment. A trace row reads ``0x605 SDO rx node 5: read 0x5FC2sub0 (C00061 Heatsink temperature)``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import datetime, timedelta
from enum import StrEnum

import can

from drivebench.protocol.abort_codes import abort_text
from drivebench.protocol.canopen.nmt import NMT_COMMAND_NAMES, NMT_STATE_NAMES, NmtCommand, NmtState
from drivebench.protocol.emcy import error_code_class, error_register_bits

NameLookup = Callable[[int, int, int], str | None]
"""(node, index, subindex) -> the profile's name for the object, e.g. ``C00061 Heatsink temperature``."""
AbortTextsLookup = Callable[[int], Mapping[int, str] | None]
"""node -> its profile's abort texts, so abort codes read in the manual's words."""
HexLookup = Callable[[int, int, int], bool]
"""(node, index, subindex) -> the object's value reads in hex (a COB-ID, a bit-coded word), not as an amount."""
EmcyLookup = Callable[[int, int, bytes], str | None]
"""(node, EMCY code, the five manufacturer-specific bytes) -> the device profile's words for it."""
"""(node, emergency code) -> the profile's text for it."""


class Service(StrEnum):
    NMT = "NMT"
    SYNC = "SYNC"
    EMCY = "EMCY"
    TIME = "TIME"
    TPDO1 = "TPDO1"
    TPDO2 = "TPDO2"
    TPDO3 = "TPDO3"
    TPDO4 = "TPDO4"
    RPDO1 = "RPDO1"
    RPDO2 = "RPDO2"
    RPDO3 = "RPDO3"
    RPDO4 = "RPDO4"
    TPDO_MORE = "TPDO5+"
    """A TPDO numbered 5 or higher (0x1804-0x19FF): never in the predefined connection set, known only from the
    device's communication parameters."""
    RPDO_MORE = "RPDO5+"
    SDO_RX = "SDO rx"
    """SDO request, client -> server (0x600 + node)."""
    SDO_TX = "SDO tx"
    """SDO response, server -> client (0x580 + node)."""
    HEARTBEAT = "Heartbeat"
    """NMT error control: heartbeat, boot-up and node guarding (0x700 + node)."""
    LSS = "LSS"
    UNKNOWN = "Unknown"
    ERROR_FRAME = "Error frame"

    @property
    def is_pdo(self) -> bool:
        return self.value[1:4] == "PDO"


# Function code (COB-ID >> 7) -> service, for COB-IDs that carry a node id in the low 7 bits.
_NODE_SERVICES = {
    0x1: Service.EMCY, 0x3: Service.TPDO1, 0x4: Service.RPDO1, 0x5: Service.TPDO2, 0x6: Service.RPDO2,
    0x7: Service.TPDO3, 0x8: Service.RPDO3, 0x9: Service.TPDO4, 0xA: Service.RPDO4, 0xB: Service.SDO_TX,
    0xC: Service.SDO_RX, 0xE: Service.HEARTBEAT,
}
LSS_SLAVE_TO_MASTER = 0x7E4
LSS_MASTER_TO_SLAVE = 0x7E5


def classify(cob_id: int, is_extended: bool = False) -> tuple[Service, int | None]:
    """Service and node id a COB-ID belongs to in the predefined connection set (29-bit ids: unknown)."""
    if is_extended:
        return Service.UNKNOWN, None
    if cob_id == 0x000:
        return Service.NMT, None
    if cob_id == 0x080:
        return Service.SYNC, None
    if cob_id == 0x100:
        return Service.TIME, None
    if cob_id in (LSS_SLAVE_TO_MASTER, LSS_MASTER_TO_SLAVE):
        return Service.LSS, None
    node = cob_id & 0x7F
    service = _NODE_SERVICES.get(cob_id >> 7)
    if service is None or node == 0:
        return Service.UNKNOWN, None
    return service, node


@dataclass(frozen=True)
class SdoContext:
    """What the SDO channel of a node was doing when a frame came: the object, and block data phase."""

    index: int
    subindex: int
    block_segment: bool = False
    """The frame is a block transfer data segment (seqno + 7 bytes), not a command."""


@dataclass(frozen=True)
class DecodedFrame:
    timestamp: float
    cob_id: int
    is_extended: bool
    is_remote: bool
    is_error: bool
    dlc: int
    data: bytes
    service: Service
    node: int | None
    summary: str
    """What the frame says, in words, without the COB-ID/service/node prefix."""

    @property
    def cob_id_text(self) -> str:
        return f"0x{self.cob_id:08X}" if self.is_extended else f"0x{self.cob_id:03X}"

    @property
    def data_hex(self) -> str:
        return self.data.hex(" ").upper()

    @property
    def text(self) -> str:
        head = f"{self.cob_id_text} {self.service.value}"
        if self.node is not None:
            head += f" node {self.node}"
        return f"{head}: {self.summary}" if self.summary else head


def _hex(data: bytes) -> str:
    return data.hex(" ").upper()


def _value_text(raw: bytes) -> str:
    value = int.from_bytes(raw, "little")
    return f"{value} (0x{value:0{2 * len(raw)}X})" if raw else "(no data)"


def _printable(raw: bytes) -> str:
    if raw and all(32 <= byte < 127 for byte in raw):
        return f" '{raw.decode('ascii')}'"
    return ""


def _hex_value(raw: bytes) -> str:
    return f"0x{int.from_bytes(raw, 'little'):0{2 * len(raw)}X}" if raw else "(no data)"


class _Objects:
    def __init__(self, node: int, names: NameLookup | None, hex_words: HexLookup | None = None) -> None:
        self.node = node
        self.names = names
        self.hex_words = hex_words

    def reads_hex(self, index: int, sub: int) -> bool:
        return self.hex_words is not None and self.hex_words(self.node, index, sub)

    def __call__(self, index: int, sub: int) -> str:
        text = f"0x{index:04X}sub{sub}"
        name = self.names(self.node, index, sub) if self.names else None
        return f"{text} ({name})" if name else text


def _abort(data: bytes, obj: _Objects, texts: Mapping[int, str] | None) -> str:
    code = int.from_bytes(data[4:8], "little")
    index, sub = int.from_bytes(data[1:3], "little"), data[3]
    return f"abort 0x{code:08X} {abort_text(code, texts)}, {obj(index, sub)}"


def _where(context: SdoContext | None, obj: _Objects) -> str:
    """The object a segment belongs to, when the tracker knows it."""
    return f" {obj(context.index, context.subindex)}" if context else ""


def _size(data: bytes, given: int) -> str:
    """The size an initiate or block initiate frame announces (bytes 4…7), when its size bit is set."""
    return f", {int.from_bytes(data[4:8], 'little')} bytes" if given else ""


def _initiate(data: bytes, obj: _Objects, verb: str, value: Callable[[bytes], str]) -> str:
    """An initiate download request or initiate upload response: the value it carries (expedited) or the size of
    the segmented transfer to come."""
    command = data[0]
    index, sub = int.from_bytes(data[1:3], "little"), data[3]
    expedited, size_given = command & 2, command & 1
    if expedited:
        raw = data[4:8 - ((command >> 2) & 3)] if size_given else data[4:8]
        return f"{verb} {obj(index, sub)} = {_hex_value(raw) if obj.reads_hex(index, sub) else value(raw)}"
    return f"{verb} {obj(index, sub)}, segmented{_size(data, size_given)}"


def _segment(data: bytes, direction: str, context: SdoContext | None, obj: _Objects) -> str:
    toggle = (data[0] >> 4) & 1
    size = 7 - ((data[0] >> 1) & 7)
    raw = data[1:1 + size]
    where, last = _where(context, obj), ", last" if data[0] & 1 else ""
    return f"{direction} segment{where} toggle {toggle}, {size} bytes{last}: {_hex(raw)}{_printable(raw)}"


def _block_segment(data: bytes, context: SdoContext, obj: _Objects) -> str:
    seqno = data[0] & 0x7F
    last = ", last" if data[0] & 0x80 else ""
    return f"block segment {seqno}{last} {obj(context.index, context.subindex)}: {_hex(data[1:8])}"


def _block_end(data: bytes, direction: str) -> str:
    """The end of a block download (client) or block upload (server): unused bytes of the last segment and CRC."""
    unused = (data[0] >> 2) & 7
    crc = int.from_bytes(data[1:3], "little")
    return f"block {direction} end, {unused} unused bytes, CRC 0x{crc:04X}"


def _sdo_request(data: bytes, context: SdoContext | None, obj: _Objects, texts: Mapping[int, str] | None) -> str:
    if context is not None and context.block_segment:
        return _block_segment(data, context, obj)
    command = data[0]
    ccs = command >> 5
    index, sub = int.from_bytes(data[1:3], "little"), data[3]
    if ccs == 1:  # initiate download
        return _initiate(data, obj, "write", lambda raw: str(int.from_bytes(raw, "little")))
    if ccs == 2:
        return f"read {obj(index, sub)}"
    if ccs == 0:
        return _segment(data, "download", context, obj)
    if ccs == 3:
        return f"upload segment request{_where(context, obj)} toggle {(command >> 4) & 1}"
    if ccs == 4:
        return _abort(data, obj, texts)
    if ccs == 5:  # block upload, client side
        cs = command & 3
        if cs == 0:
            return f"block read {obj(index, sub)}, blksize {data[4]}"
        if cs == 3:
            return "block upload start"
        if cs == 2:
            return f"block upload ack seqno {data[1]}, blksize {data[2]}"
        return "block upload end confirmed"
    if ccs == 6:  # block download, client side
        if command & 1:
            return _block_end(data, "download")
        return f"block write {obj(index, sub)}{_size(data, command & 2)}"
    return f"unknown SDO command 0x{command:02X}"


def _sdo_response(data: bytes, context: SdoContext | None, obj: _Objects, texts: Mapping[int, str] | None) -> str:
    if context is not None and context.block_segment:
        return _block_segment(data, context, obj)
    command = data[0]
    scs = command >> 5
    index, sub = int.from_bytes(data[1:3], "little"), data[3]
    if scs == 2:  # initiate upload response
        return _initiate(data, obj, "read response", _value_text)
    if scs == 3:
        return f"write response {obj(index, sub)} OK"
    if scs == 0:
        return _segment(data, "upload", context, obj)
    if scs == 1:
        return f"download segment response{_where(context, obj)} toggle {(command >> 4) & 1}"
    if scs == 4:
        return _abort(data, obj, texts)
    if scs == 5:  # block download, server side
        ss = command & 3
        if ss == 0:
            return f"block write response {obj(index, sub)}, blksize {data[4]}"
        if ss == 2:
            return f"block ack seqno {data[1]}, blksize {data[2]}"
        return "block download end confirmed"
    if scs == 6:  # block upload, server side
        if command & 1:
            return _block_end(data, "upload")
        return f"block read response {obj(index, sub)}{_size(data, command & 2)}"
    return f"unknown SDO command 0x{command:02X}"


def _nmt(data: bytes) -> tuple[int | None, str]:
    if len(data) < 2:
        return None, f"malformed NMT command {_hex(data)}"
    target = data[1]
    try:
        label = NMT_COMMAND_NAMES[NmtCommand(data[0])]
    except ValueError:
        return target or None, f"unknown NMT command 0x{data[0]:02X} to node {target}"
    if target == 0:
        return None, f"{label}: all nodes"
    return target, f"{label} {target}" if label.endswith("node") else f"{label}: node {target}"


def _heartbeat(msg: can.Message, data: bytes) -> str:
    if msg.is_remote_frame:
        return "node guarding request"
    if not data:
        return "empty heartbeat"
    state = data[0] & 0x7F
    try:
        label = NMT_STATE_NAMES[NmtState(state)]
    except ValueError:
        label = f"unknown state 0x{state:02X}"
    if state == NmtState.BOOTUP:
        return "Boot-up"
    toggle = f", toggle {data[0] >> 7}" if data[0] & 0x80 else ""
    return f"{label}{toggle}"


def _emcy(node: int, data: bytes, emcy_texts: EmcyLookup | None) -> str:
    padded = data + bytes(max(0, 8 - len(data)))
    code, register = int.from_bytes(padded[0:2], "little"), padded[2]
    if code == 0:
        return f"error reset, register 0x{register:02X}"
    text = (emcy_texts(node, code, bytes(padded[3:8])) if emcy_texts else None) or error_code_class(code)
    bits = ", ".join(error_register_bits(register)) or "no bits"
    return f"0x{code:04X} {text}, register 0x{register:02X} ({bits}), data {_hex(padded[3:8])}"


_TIME_EPOCH = datetime(1984, 1, 1)


def _time(data: bytes) -> str:
    if len(data) < 6:
        return f"malformed TIME_OF_DAY {_hex(data)}"
    ms = int.from_bytes(data[0:4], "little") & 0x0FFFFFFF
    days = int.from_bytes(data[4:6], "little")
    stamp = _TIME_EPOCH + timedelta(days=days, milliseconds=ms)
    return stamp.isoformat(sep=" ", timespec="milliseconds")


_LSS_COMMANDS = {
    0x04: "switch state global", 0x11: "configure node-ID", 0x13: "configure bit timing",
    0x15: "activate bit timing", 0x17: "store configuration", 0x40: "switch state selective vendor-ID",
    0x41: "switch state selective product code", 0x42: "switch state selective revision number",
    0x43: "switch state selective serial number", 0x44: "switch state selective response",
    0x46: "identify remote slave vendor-ID", 0x47: "identify remote slave product code",
    0x48: "identify remote slave revision low", 0x49: "identify remote slave revision high",
    0x4A: "identify remote slave serial low", 0x4B: "identify remote slave serial high",
    0x4C: "identify non-configured remote slave", 0x4F: "identify slave response",
    0x50: "non-configured slave response", 0x51: "fastscan", 0x5A: "inquire vendor-ID",
    0x5B: "inquire product code", 0x5C: "inquire revision number", 0x5D: "inquire serial number",
    0x5E: "inquire node-ID",
}


def _lss(cob_id: int, data: bytes) -> str:
    direction = "request" if cob_id == LSS_MASTER_TO_SLAVE else "response"
    if not data:
        return f"empty LSS {direction}"
    command = _LSS_COMMANDS.get(data[0], f"command 0x{data[0]:02X}")
    detail = ""
    if data[0] == 0x04 and len(data) > 1:
        detail = " configuration" if data[1] else " waiting"
    elif data[0] == 0x11 and len(data) > 1:
        detail = f" {data[1]}" if direction == "request" else f" error {data[1]}"
    elif 0x40 <= data[0] <= 0x4B or 0x5A <= data[0] <= 0x5E:
        value = int.from_bytes(data[1:5], "little")
        detail = f" 0x{value:08X}" if len(data) > 1 and (direction == "response" or data[0] < 0x5A) else ""
    return f"{direction}: {command}{detail}"


# SocketCAN error classes (linux/can/error.h), the convention python-can adapters follow for error frames.
_ERROR_CLASSES = {
    0x001: "TX timeout", 0x002: "lost arbitration", 0x004: "controller problem", 0x008: "protocol violation",
    0x010: "transceiver status", 0x020: "no ACK on transmission", 0x040: "bus off", 0x080: "bus error",
    0x100: "controller restarted",
}


def _error_frame(error_class: int, data: bytes) -> str:
    words = [text for bit, text in _ERROR_CLASSES.items() if error_class & bit] or ["unspecified"]
    return f"{', '.join(words)} (class 0x{error_class:03X}) {_hex(data)}".rstrip()


def decode_frame(msg: can.Message, *, names: NameLookup | None = None, abort_texts: AbortTextsLookup | None = None,
                 emcy_texts: EmcyLookup | None = None, sdo_context: SdoContext | None = None,
                 owner: tuple[Service, int | None] | None = None, hex_words: HexLookup | None = None) -> DecodedFrame:
    """Decode ``msg``; ``names``/``abort_texts``/``emcy_texts`` add the profile's words where a caller has them;
    ``owner`` is the service and node of a COB-ID the predefined connection set would give another node (a
    device's additional SDO channel: 0x5C5 is node 5's SDO2 answer, not node 69's; a PDO on a COB-ID of its own;
    node None where the predefined node no longer uses it); ``hex_words`` says which objects' values read in hex."""
    data = b"" if msg.is_remote_frame else bytes(msg.data)

    def make(service: Service, node: int | None, summary: str) -> DecodedFrame:
        return DecodedFrame(msg.timestamp, msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame,
                            msg.is_error_frame, msg.dlc, data, service, node, summary)

    if msg.is_error_frame:
        return make(Service.ERROR_FRAME, None, _error_frame(msg.arbitration_id, data))
    service, node = owner or classify(msg.arbitration_id, msg.is_extended_id)
    remote = f"remote request, dlc {msg.dlc}"
    if service is Service.NMT:
        target, summary = _nmt(data)
        return make(service, target, summary)
    if service is Service.SYNC:
        return make(service, None, f"counter {data[0]}" if data else "")
    if service is Service.TIME:
        return make(service, None, remote if msg.is_remote_frame else _time(data))
    if service is Service.LSS:
        return make(service, None, _lss(msg.arbitration_id, data))
    if service is Service.UNKNOWN or node is None:
        return make(Service.UNKNOWN, None, remote if msg.is_remote_frame else f"{len(data)} bytes {_hex(data)}")
    if service is Service.HEARTBEAT:
        return make(service, node, _heartbeat(msg, data))
    if msg.is_remote_frame:
        return make(service, node, remote)
    if service is Service.EMCY:
        return make(service, node, _emcy(node, data, emcy_texts))
    if service in (Service.SDO_RX, Service.SDO_TX):
        if len(data) != 8:
            return make(service, node, f"malformed SDO frame ({len(data)} bytes) {_hex(data)}")
        objects = _Objects(node, names, hex_words)
        texts = abort_texts(node) if abort_texts else None
        decoder = _sdo_request if service is Service.SDO_RX else _sdo_response
        return make(service, node, decoder(data, sdo_context, objects, texts))
    return make(service, node, f"{len(data)} bytes {_hex(data)}")


class SdoTracker:
    """Follows the SDO channels of all nodes to give each SDO frame its ``SdoContext``.

    Keeps one small record per node that used SDO (at most 127). Call ``observe`` for every frame, in bus order.
    """

    def __init__(self) -> None:
        self._object: dict[int, tuple[int, int]] = {}
        self._block: dict[int, str] = {}
        """node -> block phase: 'down' (client sends segments), 'down-last', 'up' (server sends), 'up-last'."""

    def reset(self) -> None:
        self._object.clear()
        self._block.clear()

    def observe(self, msg: can.Message) -> SdoContext | None:
        cob_id = msg.arbitration_id
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or not 0x581 <= cob_id <= 0x67F:
            return None
        node = cob_id & 0x7F
        if node == 0 or len(msg.data) != 8:
            return None
        data = msg.data
        request = cob_id >= 0x600
        command = data[0]
        phase = self._block.get(node)
        obj = self._object.get(node)
        # Block data segments: client -> server during a block download, server -> client during an upload.
        if phase in ("down", "up") and request == (phase == "down") and obj and command != 0x80:
            if command & 0x80:
                self._block[node] = phase + "-last"
            return SdoContext(obj[0], obj[1], block_segment=True)
        specifier = command >> 5
        if specifier == 4:  # abort, either side
            self._block.pop(node, None)
            return SdoContext(*obj) if obj else None
        index_sub = (int.from_bytes(data[1:3], "little"), data[3])
        subcommand = command & 3 if specifier == 5 else command & 1
        if request:
            if specifier in (1, 2) or (specifier in (5, 6) and subcommand == 0):  # initiate: a new object
                self._object[node] = index_sub
                self._block.pop(node, None)
            elif specifier == 5 and subcommand == 3:  # block upload start: the server sends segments next
                self._block[node] = "up"
            elif specifier in (5, 6) and not (specifier == 5 and subcommand == 2 and phase == "up"):
                # Block end (confirm), or the ack of the last sub-block; an ack in phase "up" asks for more.
                self._block.pop(node, None)
        elif specifier == 5 and subcommand == 0:  # block download initiate response: client sends segments
            self._block[node] = "down"
        elif specifier == 5 and subcommand == 2:  # block ack: after the last segment the end follows
            if phase != "down":
                self._block.pop(node, None)
        elif specifier == 5 or (specifier == 6 and subcommand == 1):  # block end (response)
            self._block.pop(node, None)
        current = self._object.get(node)
        return SdoContext(*current) if current else None
