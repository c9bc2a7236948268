"""CoE SDO Information service (ETG.1000.6 5.6.3) over real UDP on 127.0.0.1: the tool's client asks the simulated
8400 motec EtherCAT unit behind the simulated master's mailbox gateway. A tap between them records every datagram,
so each request and response is checked byte for byte against the standard's field tables (written out below),
including a response in fragments, the SDO Info Error request, a lost fragment and a slave without the service."""

from __future__ import annotations

import socket
import struct
import threading
from collections.abc import Callable, Iterator

import pytest

from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import SdoAbortError, SdoOutOfStepError, SdoStalledError
from drivebench.protocol.ethercat.coe_sdo import SERVICE_NOT_SUPPORTED, MailboxRefused
from drivebench.protocol.ethercat.segment import EthercatSegment
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from drivebench.transport.ethercat_gateway import GatewaySpec

STATION = 1001  # 0x03E9
SMALL_MAILBOX = 48
"""Bytes of the slave's mailbox in these tests: 48 - 6 (mailbox header) - 2 (CoE header) - 4 (SDO Info header)
leaves 36 data bytes per fragment, so the unit's OD list (36 objects: 74 bytes) comes in three fragments."""


class Tap:
    """A UDP relay between the tool and the gateway that records what passes and can drop a datagram."""

    def __init__(self, gateway_port: int) -> None:
        self.gateway = ("127.0.0.1", gateway_port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.closing = False
        self.client: tuple[str, int] | None = None
        self.requests: list[bytes] = []
        self.answers: list[bytes] = []
        self.drop_answer: Callable[[bytes], bool] = lambda datagram: False
        self.thread = threading.Thread(target=self._relay, daemon=True)
        self.thread.start()

    def _relay(self) -> None:
        while True:
            try:
                datagram, peer = self.sock.recvfrom(1500)
            except OSError:
                return
            if self.closing:
                return
            if peer == self.gateway:
                self.answers.append(datagram)
                if self.client is not None and not self.drop_answer(datagram):
                    self.sock.sendto(datagram, self.client)
            else:
                self.client = peer
                self.requests.append(datagram)
                self.sock.sendto(datagram, self.gateway)

    def close(self) -> None:
        """Wake the thread with an empty datagram, then close (closing a UDP socket does not end a recvfrom)."""
        self.closing = True
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as waker:
            waker.sendto(b"", ("127.0.0.1", self.port))
        self.thread.join(timeout=5)
        self.sock.close()


def mailbox(counter: int, mailbox_type: int, data: bytes) -> bytes:
    """ETG.8200 frame header (11-bit length, type 5) + mailbox header (length, address, channel/priority,
    type | counter << 4) + data, packed field by field from the standard's table."""
    header = struct.pack("<HHBB", len(data), STATION, 0x00, mailbox_type | counter << 4)
    return struct.pack("<H", (len(header) + len(data)) | 5 << 12) + header + data


def info(counter: int, opcode: int, data: bytes, *, incomplete: bool = False, left: int = 0) -> bytes:
    """CoE header (number 0, service 8 = SDO Information in bits 12...15) + SDO Info header (OpCode bits 0...6,
    Incomplete bit 7, reserved byte, Fragments left UINT16) + data."""
    coe_header = struct.pack("<H", 8 << 12)
    info_header = struct.pack("<BBH", opcode | (0x80 if incomplete else 0), 0, left)
    return mailbox(counter, 0x03, coe_header + info_header + data)


def counter_of(datagram: bytes) -> int:
    return datagram[2 + 5] >> 4


@pytest.fixture
def slave(registry: ProfileRegistry) -> SimulatedSlave:
    return SimulatedSlave(registry.get("lenze-8400-motec-ethercat"), STATION, 0, mailbox_size=SMALL_MAILBOX)


@pytest.fixture
def tap(slave: SimulatedSlave) -> Iterator[Tap]:
    server = GatewayServer([slave]).start()
    relay = Tap(server.port)
    yield relay
    relay.close()
    server.stop()


@pytest.fixture
def segment(tap: Tap) -> Iterator[EthercatSegment]:
    opened = EthercatSegment(GatewaySpec.parse(f"ethercat-mbg:127.0.0.1:{tap.port}"), timeout_s=2.0, retries=0,
                             mailbox_size=SMALL_MAILBOX)
    yield opened
    opened.close()


def test_od_list_in_three_fragments_byte_for_byte(registry: ProfileRegistry, tap: Tap,
                                                  segment: EthercatSegment) -> None:
    indices = segment.sdo(STATION).od_list()
    profile_indices = sorted({item.index for item in Catalog(registry.get("lenze-8400-motec-ethercat")).items})
    assert indices == profile_indices and len(indices) == 36  # the simulated unit answers from its profile

    (request,) = tap.requests
    c = counter_of(request)
    assert request == info(c, 0x01, bytes.fromhex("0100"))  # Get OD List request, list type 1: all objects
    assert request.hex(" ") == f"0e 50 08 00 e9 03 00 {0x03 | c << 4:02x} 00 80 01 00 00 00 01 00"

    words = struct.pack("<H", 1) + struct.pack(f"<{len(indices)}H", *indices)  # list type, then the indices
    assert len(tap.answers) == 3
    first, second, third = tap.answers
    assert first == info(counter_of(first), 0x02, words[:36], incomplete=True, left=2)
    assert second == info(counter_of(second), 0x02, words[36:72], incomplete=True, left=1)
    assert third == info(counter_of(third), 0x02, words[72:], left=0)
    assert first[2 + 6 + 2:2 + 6 + 6].hex(" ") == "82 00 02 00"  # OpCode 2 + Incomplete, 2 fragments left
    assert third[2 + 6 + 2:2 + 6 + 6].hex(" ") == "02 00 00 00"
    counters = segment.counters(STATION)
    assert (counters.requests, counters.responses, counters.aborts) == (1, 3, 0)


def test_od_list_lengths(segment: EthercatSegment) -> None:
    lengths = segment.sdo(STATION).od_list(0)  # list type 0: how long lists 1...5 are
    assert lengths[0] == 36 and len(lengths) == 5


def test_object_description_byte_for_byte(tap: Tap, segment: EthercatSegment) -> None:
    described = segment.sdo(STATION).object_description(0x5FD8)
    assert (described.index, described.data_type, described.max_subindex, described.object_code_text) == (
        0x5FD8, 0x0003, 1, "ARRAY")  # C00039 Fixed setpoint: INTEGER16 subcodes
    request, answer = tap.requests[0], tap.answers[0]
    assert request == info(counter_of(request), 0x03, bytes.fromhex("d8 5f"))
    # Index, Data type (0x0003 INTEGER16), Max subindex 1, Object code 8 (ARRAY), Name
    assert answer == info(counter_of(answer), 0x04, bytes.fromhex("d8 5f 03 00 01 08") + described.name.encode())
    assert described.name == "Fixed setpoint"


def test_entry_description_says_mapping_is_written_in_pre_operational_only(tap: Tap,
                                                                           segment: EthercatSegment) -> None:
    entry = segment.sdo(STATION).entry_description(0x1600, 1)
    request, answer = tap.requests[0], tap.answers[0]
    assert request == info(counter_of(request), 0x05, bytes.fromhex("00 16 01 00"))  # index, subindex, value info
    # Index, Subindex, Value info 0, Data type 0x0007 UNSIGNED32, Bit length 32, Object access 0x000F (read in
    # Pre-Op/Safe-Op/Op, write in Pre-Op only), Description
    assert answer == info(counter_of(answer), 0x06,
                          bytes.fromhex("00 16 01 00 07 00 20 00 0f 00") + b"Output object 1")
    assert (entry.data_type, entry.bit_length, entry.access, entry.name) == (7, 32, 0x000F, "Output object 1")
    c00039 = segment.sdo(STATION).entry_description(0x5FD8, 1)
    assert c00039.access == 0x003F and c00039.name == "Fixed_Setpoint_1"  # writable in every state


def test_unknown_object_answers_the_sdo_info_error_request(tap: Tap, segment: EthercatSegment) -> None:
    with pytest.raises(SdoAbortError, match="0x06020000") as refused:
        segment.sdo(STATION).object_description(0x4000)
    assert refused.value.abort_code == 0x06020000 and refused.value.index == 0x4000
    answer = tap.answers[0]
    assert answer == info(counter_of(answer), 0x07, bytes.fromhex("00 00 02 06"))  # Abort code UINT32
    assert segment.counters(STATION).aborts == 1


def test_a_lost_fragment_is_told_in_words(tap: Tap, segment: EthercatSegment) -> None:
    tap.drop_answer = lambda datagram: datagram[2 + 6 + 2:2 + 6 + 6] == bytes.fromhex("82 00 01 00")
    with pytest.raises(SdoOutOfStepError, match=r"a fragment of the SDO information response was lost \(1 "
                                                r"fragments left expected, the slave says 0\)"):
        segment.sdo(STATION).od_list()
    tap.drop_answer = lambda datagram: datagram[2 + 6 + 2:2 + 6 + 6] == bytes.fromhex("02 00 00 00")
    with pytest.raises(SdoStalledError, match=r"stopped answering during a fragmented transfer of the SDO "
                                              r"information response after 2 of 3"):
        segment.sdo(STATION).od_list()


def test_a_slave_without_the_service_answers_with_a_mailbox_error(slave: SimulatedSlave, tap: Tap,
                                                                  segment: EthercatSegment) -> None:
    slave.server.dictionary = None
    with pytest.raises(MailboxRefused, match="the service is not supported") as refused:
        segment.sdo(STATION).od_list()
    assert refused.value.code == SERVICE_NOT_SUPPORTED
    answer = tap.answers[0]
    # mailbox type 0 (error), Type 0x0001 (mailbox command), Detail 0x0004 (service not supported)
    assert answer == mailbox(counter_of(answer), 0x00, bytes.fromhex("01 00 04 00"))


def test_entry_description_with_default_minimum_and_maximum(tap: Tap, segment: EthercatSegment) -> None:
    asked = 0x10 | 0x20 | 0x40  # value info: default, minimum, maximum
    entry = segment.sdo(STATION).entry_description(0x29C2, 0, asked)  # C13885 Clear process data: 0 ... 1, default 1
    request, answer = tap.requests[0], tap.answers[0]
    assert request == info(counter_of(request), 0x05, bytes.fromhex("c2 29 00 70"))
    # Index, Subindex, Value info 0x70, UNSIGNED8, 8 bits, access 0x003F, default 1, minimum 0, maximum 1, name
    assert answer == info(counter_of(answer), 0x06, bytes.fromhex("c2 29 00 70 05 00 08 00 3f 00 01 00 01")
                          + b"Clear process data")
    assert (entry.value_info, entry.values, entry.name) == (0x70, b"\x01\x00\x01", "Clear process data")
