"""The SDO server on a real python-can ``virtual`` bus, against canopen 2.4.1's SDO client and raw frames.

Every test records the frames on the wire and asserts exact bytes. The manuals' examples live in
``tests/vectors/manual_sdo.py``; where a manual leaves a node id or value out, or prints a frame with 7 bytes (the
MICROMASTER traces), the vector says so and the test sends CiA 301's 8 bytes.
"""

from __future__ import annotations

import itertools
import struct
from collections.abc import Iterator

import can
import canopen
import pytest
from canopen.objectdictionary import ObjectDictionary
from canopen.sdo.exceptions import SdoAbortedError

from drivebench.protocol.canopen.sdo_server import SdoAbort, SdoServer, crc16_ccitt
from tests.vectors.manual_sdo import ALL, MICROMASTER, Frame, SdoVector

_channels = itertools.count()
TIMEOUT = 2.0


class ObjectStore:
    """A plain object dictionary for the server: values as bytes, with CiA 301 aborts for bad access."""

    def __init__(self, values: dict[tuple[int, int], bytes], *, read_only: set[tuple[int, int]] | None = None,
                 write_only: set[tuple[int, int]] | None = None) -> None:
        self.values = dict(values)
        self.read_only = read_only or set()
        self.write_only = write_only or set()

    def _check(self, index: int, subindex: int) -> None:
        if not any(key[0] == index for key in self.values):
            raise SdoAbort(0x06020000)
        if (index, subindex) not in self.values:
            raise SdoAbort(0x06090011)

    def read(self, index: int, subindex: int) -> bytes:
        self._check(index, subindex)
        if (index, subindex) in self.write_only:
            raise SdoAbort(0x06010001)
        return self.values[(index, subindex)]

    def write(self, index: int, subindex: int, data: bytes) -> None:
        self._check(index, subindex)
        if (index, subindex) in self.read_only:
            raise SdoAbort(0x06010002)
        self.values[(index, subindex)] = data


class Wire:
    """A server node, a raw client and a recorder on one virtual channel; canopen's client on demand."""

    def __init__(self, node: int, objects: ObjectStore, **options: object) -> None:
        self.channel = f"sdo-server-{next(_channels)}"
        self.objects = objects
        self.errors: list[BaseException] = []
        self._server_bus = can.Bus(interface="virtual", channel=self.channel)
        self.server = SdoServer(node, self._send, objects, **options)  # type: ignore[arg-type]
        self._notifier = can.Notifier(self._server_bus, [self._on_message], timeout=0.05)
        self.recorder = can.Bus(interface="virtual", channel=self.channel)
        self.client = can.Bus(interface="virtual", channel=self.channel)
        self.network: canopen.Network | None = None

    def _send(self, cob_id: int, data: bytes) -> None:
        assert len(data) == 8, f"SDO frame with {len(data)} bytes"
        self._server_bus.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))

    def _on_message(self, message: can.Message) -> None:
        if message.arbitration_id != self.server.rx_cob:
            return
        try:
            self.server.on_request(bytes(message.data))
        except BaseException as exc:  # surfaced by close(); the notifier thread would swallow it
            self.errors.append(exc)

    def canopen_node(self) -> canopen.RemoteNode:
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.05  # its notifier thread polls the bus; 1 s would slow every teardown
        self.network.connect(interface="virtual", channel=self.channel)
        node = self.network.add_node(canopen.RemoteNode(self.server.node_id, ObjectDictionary()))
        node.sdo.RESPONSE_TIMEOUT = TIMEOUT
        return node

    def send(self, hex_bytes: str) -> None:
        data = bytes.fromhex(hex_bytes)
        self.client.send(can.Message(arbitration_id=self.server.rx_cob, data=data, is_extended_id=False))

    def receive(self) -> str:
        while (message := self.client.recv(timeout=TIMEOUT)) is not None:
            if message.arbitration_id == self.server.tx_cob:
                return bytes(message.data).hex(" ").upper()
        raise AssertionError("no SDO response")

    def exchange(self, hex_bytes: str) -> str:
        self.send(hex_bytes)
        return self.receive()

    def assert_silent(self) -> None:
        message = self.client.recv(timeout=0.2)
        assert message is None, f"unexpected frame {message}"

    def recorded(self) -> list[tuple[int, bytes]]:
        frames = []
        while (message := self.recorder.recv(timeout=0.05)) is not None:
            frames.append((message.arbitration_id, bytes(message.data)))
        return frames

    def close(self) -> None:
        if self.network is not None:
            self.network.disconnect()
        self._notifier.stop()
        for bus in (self._server_bus, self.recorder, self.client):
            bus.shutdown()
        assert not self.errors, self.errors


@pytest.fixture
def wires() -> Iterator[list[Wire]]:
    opened: list[Wire] = []
    yield opened
    for wire in opened:
        wire.close()


def _options(vector: SdoVector) -> dict[str, object]:
    """MICROMASTER answers expedited transfers only (seed003 §5); the Lenze devices do all of CiA 301."""
    if vector in MICROMASTER:
        return {"segmented": False, "block": False}
    return {}


def _wire_for(vector: SdoVector, wires: list[Wire]) -> Wire:
    initial = vector.value if vector.direction == "upload" else bytes(len(vector.value))
    wire = Wire(vector.node, ObjectStore({(vector.index, vector.subindex): initial}), **_options(vector))
    wires.append(wire)
    return wire


def _assert_frames(recorded: list[tuple[int, bytes]], expected: list[Frame]) -> None:
    shown = [str(Frame(cob, data)) for cob, data in recorded]
    assert len(recorded) == len(expected), shown
    for (cob, data), frame in zip(recorded, expected, strict=True):
        assert frame.matches(cob, data), f"{Frame(cob, data)} != {frame}\n{shown}"


# --- the manuals' examples ---------------------------------------------------------------------------------
@pytest.mark.parametrize("vector", ALL, ids=lambda v: v.id)
def test_manual_example_frame_by_frame(vector: SdoVector, wires: list[Wire]) -> None:
    """Replay the manual's requests byte for byte; every response is the one the manual prints."""
    wire = _wire_for(vector, wires)
    for request, response in vector.exchanges:
        assert request.cob_id == wire.server.rx_cob
        answer = bytes.fromhex(wire.exchange(request.data.hex()))
        assert response.matches(wire.server.tx_cob, answer), f"{answer.hex(' ')} != {response}"
    assert wire.objects.values[(vector.index, vector.subindex)] == vector.value


def _canopen_sends_the_manual_requests(vector: SdoVector) -> bool:
    # canopen always indicates the size of an expedited download; the MICROMASTER trace's 0x22 does not.
    return vector.direction == "upload" or bool(vector.request.data[0] & 0x01)


@pytest.mark.parametrize("vector", [v for v in ALL if _canopen_sends_the_manual_requests(v)], ids=lambda v: v.id)
def test_manual_example_through_canopen_client(vector: SdoVector, wires: list[Wire]) -> None:
    """canopen's client, talking to the server, puts exactly the manual's frames on the wire."""
    wire = _wire_for(vector, wires)
    node = wire.canopen_node()
    if vector.direction == "upload":
        assert node.sdo.upload(vector.index, vector.subindex) == vector.value
    else:
        node.sdo.download(vector.index, vector.subindex, vector.value)
        assert wire.objects.values[(vector.index, vector.subindex)] == vector.value
    _assert_frames(wire.recorded(), [frame for exchange in vector.exchanges for frame in exchange])


def test_expedited_p1501_write_without_size_takes_four_bytes(wires: list[Wire]) -> None:
    """MICROMASTER trace: ``22 dd 25 00 0c 00 2b 08`` (e = 1, s = 0) writes all four bytes (CiA 301)."""
    vector = next(v for v in MICROMASTER if v.id == "mm4-p1501-bico")
    wire = _wire_for(vector, wires)
    assert wire.exchange("22 dd 25 00 0c 00 2b 08") == "60 DD 25 00 00 00 00 00"
    assert wire.objects.values[(0x25DD, 0)] == (0x082B000C).to_bytes(4, "little")


# --- expedited and segmented -------------------------------------------------------------------------------
@pytest.mark.parametrize(("value", "response"), [
    (b"\x2a", "4F 00 20 01 2A 00 00 00"),
    (b"\x34\x12", "4B 00 20 01 34 12 00 00"),
    (b"\x01\x02\x03", "47 00 20 01 01 02 03 00"),
    (b"\x01\x02\x03\x04", "43 00 20 01 01 02 03 04"),
])
def test_expedited_upload_indicates_the_size(value: bytes, response: str, wires: list[Wire]) -> None:
    wire = Wire(1, ObjectStore({(0x2000, 1): value}))
    wires.append(wire)
    assert wire.exchange("40 00 20 01 00 00 00 00") == response


def test_expedited_upload_without_size_when_the_device_does_not_indicate_it(wires: list[Wire]) -> None:
    wire = Wire(1, ObjectStore({(0x2000, 1): b"\x34\x12"}), expedited_size_indicated=False)
    wires.append(wire)
    assert wire.exchange("40 00 20 01 00 00 00 00") == "42 00 20 01 34 12 00 00"


def test_segmented_download_through_canopen(wires: list[Wire]) -> None:
    """20 bytes: initiate 0x21 with size, segments 0x00/0x10 (7 bytes) and 0x03 (6 bytes, last), acks 0x20/0x30."""
    text = b"DriveBench test 1234"
    wire = Wire(7, ObjectStore({(0x2001, 0): b""}))
    wires.append(wire)
    wire.canopen_node().sdo.download(0x2001, 0, text)
    assert wire.objects.values[(0x2001, 0)] == text
    _assert_frames(wire.recorded(), [
        Frame(0x607, bytes.fromhex("21 01 20 00 14 00 00 00")), Frame(0x587, bytes.fromhex("60 01 20 00 00 00 00 00")),
        Frame(0x607, b"\x00" + text[0:7]), Frame(0x587, bytes.fromhex("20 00 00 00 00 00 00 00")),
        Frame(0x607, b"\x10" + text[7:14]), Frame(0x587, bytes.fromhex("30 00 00 00 00 00 00 00")),
        Frame(0x607, b"\x03" + text[14:20] + b"\x00"), Frame(0x587, bytes.fromhex("20 00 00 00 00 00 00 00")),
    ])


def test_segmented_upload_of_empty_value_sends_one_empty_last_segment(wires: list[Wire]) -> None:
    wire = Wire(1, ObjectStore({(0x2001, 0): b""}))
    wires.append(wire)
    assert wire.exchange("40 01 20 00 00 00 00 00") == "41 01 20 00 00 00 00 00"
    assert wire.exchange("60 00 00 00 00 00 00 00") == "0F 00 00 00 00 00 00 00"


def test_segmented_download_shorter_than_indicated_aborts(wires: list[Wire]) -> None:
    wire = Wire(1, ObjectStore({(0x2001, 0): b""}))
    wires.append(wire)
    assert wire.exchange("21 01 20 00 0A 00 00 00") == "60 01 20 00 00 00 00 00"
    assert wire.exchange("01 41 42 43 44 45 46 47") == "80 01 20 00 13 00 07 06"
    assert wire.objects.values[(0x2001, 0)] == b""


# --- aborts ------------------------------------------------------------------------------------------------
@pytest.fixture
def lenze(wires: list[Wire]) -> Wire:
    """A node 5 with C00061 (ro), C00088 (rw), C00099 (11 chars) and a write-only object."""
    objects = ObjectStore({(0x5FC2, 0): (43).to_bytes(4, "little"), (0x5FA7, 0): (1020).to_bytes(4, "little"),
                           (0x5F9C, 0): b"01.00.00.00", (0x5FFD, 0): b"\x00"},
                          read_only={(0x5FC2, 0), (0x5F9C, 0)}, write_only={(0x5FFD, 0)})
    wire = Wire(5, objects)
    wires.append(wire)
    return wire


@pytest.mark.parametrize(("request_hex", "abort_hex"), [
    pytest.param("40 00 30 00 00 00 00 00", "80 00 30 00 00 00 02 06", id="unknown-object-0x06020000"),
    pytest.param("40 C2 5F 07 00 00 00 00", "80 C2 5F 07 11 00 09 06", id="unknown-sub-0x06090011"),
    pytest.param("2F C2 5F 00 2A 00 00 00", "80 C2 5F 00 02 00 01 06", id="write-read-only-0x06010002"),
    pytest.param("40 FD 5F 00 00 00 00 00", "80 FD 5F 00 01 00 01 06", id="read-write-only-0x06010001"),
    pytest.param("E0 A7 5F 00 00 00 00 00", "80 A7 5F 00 01 00 04 05", id="unknown-ccs-0x05040001"),
    pytest.param("60 00 00 00 00 00 00 00", "80 00 00 00 01 00 04 05", id="segment-without-transfer"),
    pytest.param("00 41 42 43 44 45 46 47", "80 00 00 00 01 00 04 05", id="download-segment-without-transfer"),
])
def test_abort_frames(request_hex: str, abort_hex: str, lenze: Wire) -> None:
    """Abort = 0x80, index, subindex, code little-endian (8400 manual ch. 9.2.4: 0x06040041 -> 41 00 04 06)."""
    assert lenze.exchange(request_hex) == abort_hex


@pytest.mark.parametrize(("index", "subindex", "code"), [(0x3000, 0, 0x06020000), (0x5FC2, 7, 0x06090011)],
                         ids=["unknown-object", "unknown-sub"])
def test_canopen_client_sees_the_abort_code(index: int, subindex: int, code: int, lenze: Wire) -> None:
    with pytest.raises(SdoAbortedError) as raised:
        lenze.canopen_node().sdo.upload(index, subindex)
    assert raised.value.code == code


def test_write_to_read_only_object_through_canopen(lenze: Wire) -> None:
    with pytest.raises(SdoAbortedError) as raised:
        lenze.canopen_node().sdo.download(0x5FC2, 0, b"\x00\x00\x00\x00")
    assert raised.value.code == 0x06010002
    assert lenze.objects.values[(0x5FC2, 0)] == (43).to_bytes(4, "little")


def test_toggle_bit_not_alternated_aborts_the_upload(lenze: Wire) -> None:
    assert lenze.exchange("40 9C 5F 00 00 00 00 00") == "41 9C 5F 00 0B 00 00 00"
    assert lenze.exchange("60 00 00 00 00 00 00 00") == "00 30 31 2E 30 30 2E 30"
    assert lenze.exchange("60 00 00 00 00 00 00 00") == "80 9C 5F 00 00 00 03 05"
    assert not lenze.server.busy


def test_toggle_bit_not_alternated_aborts_the_download(lenze: Wire) -> None:
    assert lenze.exchange("21 A7 5F 00 0E 00 00 00") == "60 A7 5F 00 00 00 00 00"
    assert lenze.exchange("10 41 42 43 44 45 46 47") == "80 A7 5F 00 00 00 03 05"
    assert lenze.objects.values[(0x5FA7, 0)] == (1020).to_bytes(4, "little")


def test_client_abort_ends_the_transfer_silently(lenze: Wire) -> None:
    assert lenze.exchange("40 9C 5F 00 00 00 00 00") == "41 9C 5F 00 0B 00 00 00"
    lenze.send("80 9C 5F 00 00 00 04 05")
    lenze.assert_silent()
    assert lenze.exchange("60 00 00 00 00 00 00 00") == "80 00 00 00 01 00 04 05"


def test_frames_shorter_than_eight_bytes_are_ignored(lenze: Wire) -> None:
    """The MICROMASTER trace prints a 7-byte read request; on the bus CiA 301 SDO frames have 8 bytes."""
    lenze.send("40 C2 5F 00 00 00 00")
    lenze.assert_silent()


# --- expedited-only device (MICROMASTER) -------------------------------------------------------------------
@pytest.fixture
def micromaster(wires: list[Wire]) -> Wire:
    objects = ObjectStore({(0x1008, 0): b"MICROMASTER 4", (0x27F9, 0): b"\xff\xff"})
    wire = Wire(3, objects, segmented=False, block=False)
    wires.append(wire)
    return wire


def test_expedited_only_device_refuses_segmented_download(micromaster: Wire) -> None:
    """seed003 §5: 'only expedited'; the manual names no code for a segmented request, CiA 301's is 0x05040001."""
    assert micromaster.exchange("21 08 10 00 0D 00 00 00") == "80 08 10 00 01 00 04 05"


def test_expedited_only_device_cannot_upload_more_than_four_bytes(micromaster: Wire) -> None:
    assert micromaster.exchange("40 08 10 00 00 00 00 00") == "80 08 10 00 00 00 01 06"


@pytest.mark.parametrize("request_hex", ["A4 F9 27 00 7F 00 00 00", "C6 F9 27 00 02 00 00 00"])
def test_expedited_only_device_refuses_block_transfers(request_hex: str, micromaster: Wire) -> None:
    assert micromaster.exchange(request_hex) == "80 F9 27 00 01 00 04 05"


# --- block transfer ----------------------------------------------------------------------------------------
def test_crc_is_crc16_ccitt_as_cia_301_specifies() -> None:
    """CRC-16/XMODEM (poly 0x1021, init 0): the catalogue check value of '123456789' is 0x31C3."""
    assert crc16_ccitt(b"123456789") == 0x31C3
    assert crc16_ccitt(b"") == 0


def _blob(size: int) -> bytes:
    return bytes((i * 37 + 11) % 256 for i in range(size))


def _segment_frames(cob: int, data: bytes, block_size: int) -> list[Frame]:
    """The sub-block segments CiA 301 prescribes: seqno 1..blksize per sub-block, bit 7 on the very last."""
    chunks = [data[i:i + 7] for i in range(0, len(data), 7)]
    return [Frame(cob, bytes([(n % block_size) + 1 | (0x80 if n == len(chunks) - 1 else 0)]) + chunk.ljust(7, b"\0"))
            for n, chunk in enumerate(chunks)]


@pytest.mark.parametrize("size", [100, 1024])
def test_block_upload_through_canopen(size: int, wires: list[Wire]) -> None:
    data = _blob(size)
    wire = Wire(9, ObjectStore({(0x2002, 0): data}))
    wires.append(wire)
    with wire.canopen_node().sdo.open(0x2002, 0, "rb", block_transfer=True) as stream:
        assert stream.read() == data
    segments = _segment_frames(0x589, data, 127)
    unused = 7 - (len(data) % 7 or 7)
    expected = [Frame(0x609, bytes.fromhex("A4 02 20 00 7F 00 00 00")),
                Frame(0x589, bytes.fromhex("C6 02 20 00") + struct.pack("<I", size)),
                Frame(0x609, bytes.fromhex("A3 00 00 00 00 00 00 00"))]
    for start in range(0, len(segments), 127):
        block = segments[start:start + 127]
        expected += [*block, Frame(0x609, bytes([0xA2, len(block), 0x7F]) + bytes(5))]
    expected += [Frame(0x589, bytes([0xC1 | unused << 2]) + struct.pack("<H", crc16_ccitt(data)) + bytes(5)),
                 Frame(0x609, bytes.fromhex("A1 00 00 00 00 00 00 00"))]
    _assert_frames(wire.recorded(), expected)
    assert not wire.server.busy


@pytest.mark.parametrize("size", [100, 1024])
def test_block_download_through_canopen(size: int, wires: list[Wire]) -> None:
    data = _blob(size)
    wire = Wire(9, ObjectStore({(0x2002, 0): b""}))
    wires.append(wire)
    with wire.canopen_node().sdo.open(0x2002, 0, "wb", size=size, block_transfer=True) as stream:
        stream.write(data)
    assert wire.objects.values[(0x2002, 0)] == data
    segments = _segment_frames(0x609, data, 127)
    unused = 7 - (len(data) % 7 or 7)
    expected = [Frame(0x609, bytes.fromhex("C6 02 20 00") + struct.pack("<I", size)),
                Frame(0x589, bytes.fromhex("A4 02 20 00 7F 00 00 00"))]
    for start in range(0, len(segments), 127):
        block = segments[start:start + 127]
        expected += [*block, Frame(0x589, bytes([0xA2, len(block), 0x7F]) + bytes(5))]
    expected += [Frame(0x609, bytes([0xC1 | unused << 2]) + struct.pack("<H", crc16_ccitt(data)) + bytes(5)),
                 Frame(0x589, bytes.fromhex("A1 00 00 00 00 00 00 00"))]
    _assert_frames(wire.recorded(), expected)


@pytest.fixture
def blocks(wires: list[Wire]) -> Wire:
    """Node 9, 0x2002 holds 50 bytes (8 segments); the server asks for sub-blocks of 4 segments."""
    wire = Wire(9, ObjectStore({(0x2002, 0): _blob(50), (0x2003, 0): b"01.00.00.00", (0x2004, 0): b"\x34\x12"}),
                block_size=4)
    wires.append(wire)
    return wire


def _segment(seqno: int, data: bytes, last: bool = False) -> str:
    return (bytes([seqno | (0x80 if last else 0)]) + data.ljust(7, b"\0")).hex(" ").upper()


def test_block_upload_repeats_segments_after_ackseq(blocks: Wire) -> None:
    data = _blob(50)
    chunks = [data[i:i + 7] for i in range(0, 50, 7)]
    assert blocks.exchange("A4 02 20 00 04 00 00 00") == "C6 02 20 00 32 00 00 00"
    blocks.send("A3 00 00 00 00 00 00 00")
    assert [blocks.receive() for _ in range(4)] == [_segment(n + 1, chunks[n]) for n in range(4)]
    blocks.send("A2 02 04 00 00 00 00 00")  # only segments 1, 2 arrived: the server starts again at chunk 3
    assert [blocks.receive() for _ in range(4)] == [_segment(n + 1, chunks[n + 2]) for n in range(4)]
    blocks.send("A2 04 04 00 00 00 00 00")
    assert [blocks.receive() for _ in range(2)] == [_segment(1, chunks[6]), _segment(2, chunks[7], last=True)]
    crc = crc16_ccitt(data)
    assert blocks.exchange("A2 02 04 00 00 00 00 00") == f"D9 {crc & 0xFF:02X} {crc >> 8:02X} 00 00 00 00 00"
    blocks.send("A1 00 00 00 00 00 00 00")
    blocks.assert_silent()
    assert not blocks.server.busy


def test_block_download_drops_out_of_sequence_segments(blocks: Wire) -> None:
    data = _blob(28)
    chunks = [data[i:i + 7] for i in range(0, 28, 7)]
    assert blocks.exchange("C6 02 20 00 1C 00 00 00") == "A4 02 20 00 04 00 00 00"
    blocks.send(_segment(1, chunks[0]))
    blocks.send(_segment(3, chunks[2]))  # segment 2 lost
    assert blocks.exchange(_segment(4, chunks[3], last=True)) == "A2 01 04 00 00 00 00 00"
    blocks.send(_segment(1, chunks[1]))
    blocks.send(_segment(2, chunks[2]))
    assert blocks.exchange(_segment(3, chunks[3], last=True)) == "A2 03 04 00 00 00 00 00"
    crc = crc16_ccitt(data)
    assert blocks.exchange(f"C1 {crc & 0xFF:02X} {crc >> 8:02X} 00 00 00 00 00") == "A1 00 00 00 00 00 00 00"
    assert blocks.objects.values[(0x2002, 0)] == data


def test_block_download_with_wrong_crc_aborts(blocks: Wire) -> None:
    assert blocks.exchange("C6 02 20 00 03 00 00 00") == "A4 02 20 00 04 00 00 00"
    assert blocks.exchange(_segment(1, b"abc", last=True)) == "A2 01 04 00 00 00 00 00"
    wrong = crc16_ccitt(b"abc") ^ 0xFFFF
    assert blocks.exchange(f"D1 {wrong & 0xFF:02X} {wrong >> 8:02X} 00 00 00 00 00") == "80 02 20 00 04 00 04 05"
    assert blocks.objects.values[(0x2002, 0)] == _blob(50)


def test_block_upload_with_invalid_block_size_aborts(blocks: Wire) -> None:
    assert blocks.exchange("A4 02 20 00 00 00 00 00") == "80 02 20 00 02 00 04 05"
    assert blocks.exchange("A4 02 20 00 80 00 00 00") == "80 02 20 00 02 00 04 05"


def test_block_upload_protocol_switch_to_segmented(blocks: Wire) -> None:
    """11 bytes with threshold 20: the server answers a normal upload (0x41) and the client goes segmented."""
    assert blocks.exchange("A4 03 20 00 7F 14 00 00") == "41 03 20 00 0B 00 00 00"
    assert blocks.exchange("60 00 00 00 00 00 00 00") == "00 30 31 2E 30 30 2E 30"
    assert blocks.exchange("70 00 00 00 00 00 00 00") == "17 30 2E 30 30 00 00 00"


def test_block_upload_protocol_switch_to_expedited(blocks: Wire) -> None:
    assert blocks.exchange("A4 04 20 00 7F 04 00 00") == "4B 04 20 00 34 12 00 00"


def test_block_upload_above_the_threshold_stays_block(blocks: Wire) -> None:
    assert blocks.exchange("A4 03 20 00 7F 0A 00 00") == "C6 03 20 00 0B 00 00 00"
