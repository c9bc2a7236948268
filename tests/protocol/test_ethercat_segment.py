"""SDO to slaves behind a mailbox gateway over real UDP on 127.0.0.1: answers matched by station address, two
slaves at once, emergencies between answers, and a gateway that is not there."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

import pytest

from drivebench.errors import SdoAbortError, SdoTimeoutError
from drivebench.protocol.ethercat import coe
from drivebench.protocol.ethercat.coe_server import Abort, CoeSdoServer
from drivebench.protocol.ethercat.segment import EthercatSegment
from drivebench.transport.ethercat_gateway import GatewaySpec, gateway_frame, telegram_of
from tests.conftest import wait_until


class Gateway:
    """A gateway on a free UDP port routing telegrams to CoE SDO servers by station address."""

    def __init__(self, slaves: dict[int, dict[tuple[int, int], bytes]]) -> None:
        self.objects = slaves
        self.servers = {station: CoeSdoServer(station, self._reader(station), self._writer(station))
                        for station in slaves}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.closing = False
        self.client: tuple[str, int] | None = None
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _reader(self, station: int):  # type: ignore[no-untyped-def]
        def read(index: int, subindex: int) -> bytes:
            try:
                return self.objects[station][index, subindex]
            except KeyError:
                raise Abort(0x06020000) from None
        return read

    def _writer(self, station: int):  # type: ignore[no-untyped-def]
        def write(index: int, subindex: int, data: bytes) -> None:
            self.objects[station][index, subindex] = data
        return write

    def _serve(self) -> None:
        while True:
            try:
                datagram, self.client = self.sock.recvfrom(1500)
            except OSError:
                return
            if self.closing:
                return
            telegram = telegram_of(datagram)
            server = self.servers.get(coe.Mailbox.decode(telegram).address)
            answer = server.handle(telegram) if server else None
            if answer is not None:
                self.sock.sendto(gateway_frame(answer), self.client)

    def emergency(self, station: int, code: int) -> None:
        assert self.client is not None
        body = coe.emergency(code, 0x01, bytes.fromhex("003181BC01"))
        self.sock.sendto(gateway_frame(coe.coe_mailbox(station, coe.CoeService.EMERGENCY, body)), self.client)

    def close(self) -> None:
        """Wake the thread with an empty datagram, then close (closing a UDP socket does not end a recvfrom)."""
        self.closing = True
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as waker:
            waker.sendto(b"", ("127.0.0.1", self.port))
        self.thread.join(timeout=5)
        self.sock.close()


@pytest.fixture
def gateway() -> Iterator[Gateway]:
    served = Gateway({1001: {(0x5FD8, 1): b"\xa0\x0f"}, 1002: {(0x5FD8, 1): b"\x10\x27", (0x29B2, 0): b"x" * 300}})
    yield served
    served.close()


@pytest.fixture
def segment(gateway: Gateway) -> Iterator[EthercatSegment]:
    opened = EthercatSegment(GatewaySpec.parse(f"ethercat-mbg:127.0.0.1:{gateway.port}"), timeout_s=2.0)
    yield opened
    opened.close()


def test_each_slave_answers_for_itself_over_udp(segment: EthercatSegment) -> None:
    assert segment.sdo(1001).upload(0x5FD8, 1) == b"\xa0\x0f"
    assert segment.sdo(1002).upload(0x5FD8, 1) == b"\x10\x27"
    assert segment.sdo(1002).upload(0x29B2, 0) == b"x" * 300  # segmented through the gateway
    segment.sdo(1001).download(0x5FD8, 1, b"\x88\x13")
    assert segment.sdo(1001).upload(0x5FD8, 1) == b"\x88\x13"
    with pytest.raises(SdoAbortError, match="does not exist"):
        segment.sdo(1001).upload(0x29B2, 0)
    counters = segment.counters(1001)
    assert (counters.requests, counters.responses, counters.aborts) == (4, 4, 1)


def test_two_slaves_are_read_at_the_same_time(segment: EthercatSegment) -> None:
    results: dict[int, list[bytes]] = {1001: [], 1002: []}

    def read_many(station: int) -> None:
        for _ in range(50):
            with segment.lock(station):
                results[station].append(segment.sdo(station).upload(0x5FD8, 1))

    threads = [threading.Thread(target=read_many, args=(station,)) for station in results]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    assert results == {1001: [b"\xa0\x0f"] * 50, 1002: [b"\x10\x27"] * 50}


def test_an_emergency_goes_to_the_listeners_not_to_the_waiting_transfer(gateway: Gateway,
                                                                      segment: EthercatSegment) -> None:
    heard: list[tuple[int, int]] = []
    segment.add_emergency_listener(lambda station, code, register, data, when: heard.append((station, code)))
    assert segment.sdo(1002).upload(0x5FD8, 1) == b"\x10\x27"
    gateway.emergency(1002, 0x1000)
    assert wait_until(lambda: bool(heard), 5), "the emergency did not arrive"
    assert heard == [(1002, 0x1000)] and segment.counters(1002).emergencies == 1
    assert segment.sdo(1002).upload(0x5FD8, 1) == b"\x10\x27"


def test_no_gateway_on_the_port_is_a_timeout_in_words() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    segment = EthercatSegment(GatewaySpec.parse(f"ethercat-mbg:127.0.0.1:{port}"), timeout_s=0.05, retries=1)
    with contextlib.closing(segment):
        with pytest.raises(SdoTimeoutError, match=r"Slave 1001 did not answer .* 0x5FD8sub1"):
            segment.sdo(1001).upload(0x5FD8, 1)
        assert segment.link.unreachable == "nothing listens on the gateway's UDP port"


@pytest.mark.parametrize(("text", "error"), [("ethercat-mbg:", "not a mailbox gateway"),
                                             ("ethercat-mbg:10.0.0.1:99999", "not between 1 and 65535"),
                                             ("ethercat:eth0", "not a mailbox gateway")])
def test_gateway_specs_are_checked_in_words(text: str, error: str) -> None:
    from drivebench.errors import BusSpecError

    with pytest.raises(BusSpecError, match=error):
        GatewaySpec.parse(text)
    assert str(GatewaySpec.parse("ethercat-mbg:plc-line3")) == "ethercat-mbg:plc-line3:34980"
