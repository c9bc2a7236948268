"""The socketcand hub through python-can's own ``socketcand`` client: relaying, isolation, bad input, overrun,
shutdown, and bridging a python-can bus."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator

import can
import pytest

from drivebench.transport.bus import BusSpec, open_bus
from drivebench.transport.hub import HubHandle, HubStats, start_hub_thread
from drivebench.transport.hub_bridge import BusBridge
from tests.conftest import fresh_channel, wait_until

DEADLINE_S = 10.0


def wait_for(check: Callable[[], object], timeout_s: float = DEADLINE_S, what: str = "condition") -> None:
    assert wait_until(lambda: bool(check()), timeout_s), f"{what}: not met within {timeout_s} s"


def connect(hub: HubHandle, channel: str = "can0") -> can.BusABC:
    return can.Bus(interface="socketcand", host="127.0.0.1", port=hub.port, channel=channel)


def members(hub: HubHandle, channel: str = "can0") -> int:
    return hub.stats().clients_per_channel.get(channel, 0)


def receive(bus: can.BusABC, count: int, timeout_s: float = DEADLINE_S) -> list[can.Message]:
    received: list[can.Message] = []
    deadline = time.monotonic() + timeout_s
    while len(received) < count and time.monotonic() < deadline:
        msg = bus.recv(0.1)
        if msg is not None:
            received.append(msg)
    assert len(received) == count, f"received {len(received)} of {count} frames"
    return received


def frame_of(msg: can.Message) -> tuple[int, bool, bytes, bool]:
    return msg.arbitration_id, msg.is_extended_id, bytes(msg.data), msg.is_error_frame


@pytest.fixture
def hub() -> Iterator[HubHandle]:
    handle = start_hub_thread(port=0)
    yield handle
    handle.stop()


@pytest.fixture
def pair(hub: HubHandle) -> Iterator[tuple[can.BusABC, can.BusABC]]:
    first, second = connect(hub), connect(hub)
    try:
        wait_for(lambda: members(hub) == 2, what="both clients joined can0")
        yield first, second
    finally:
        first.shutdown()
        second.shutdown()


class RawClient:
    """A socketcand client written by hand, to send what python-can would never send and to read slowly."""

    def __init__(self, port: int, channel: str = "can0", receive_buffer: int | None = None) -> None:
        self.sock = socket.socket()
        if receive_buffer is not None:  # before connect, so the window stays small
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        self.sock.settimeout(DEADLINE_S)
        self.sock.connect(("127.0.0.1", port))
        assert self.sock.recv(256) == b"< hi >"
        self.command(f"< open {channel} >", b"< ok >")
        self.command("< rawmode >", b"< ok >")

    def command(self, text: str, reply: bytes) -> None:
        self.sock.sendall(text.encode("ascii"))
        assert self.sock.recv(256) == reply

    @property
    def address(self) -> str:
        host, port = self.sock.getsockname()
        return f"{host}:{port}"

    def close(self) -> None:
        self.sock.close()


# --- relaying ----------------------------------------------------------------------------------------
SENT = [
    can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes.fromhex("40C25F0000000000")),
    can.Message(arbitration_id=0x18FF0105, is_extended_id=True, data=bytes.fromhex("0102")),
    can.Message(arbitration_id=0x7E5, is_extended_id=False, data=b""),
    can.Message(arbitration_id=0x5, is_extended_id=True, data=b""),
]


def test_frames_relay_both_ways_with_standard_extended_and_empty_frames(
        hub: HubHandle, pair: tuple[can.BusABC, can.BusABC]) -> None:
    first, second = pair
    for msg in SENT:
        first.send(msg)
    assert [frame_of(m) for m in receive(second, len(SENT))] == [frame_of(m) for m in SENT]

    reply = can.Message(arbitration_id=0x585, is_extended_id=False, data=bytes.fromhex("43C25F002B000000"))
    second.send(reply)
    (answer,) = receive(first, 1)
    assert frame_of(answer) == frame_of(reply), "the sender's own frames never come back before the reply"
    assert abs(answer.timestamp - time.time()) < 60, "frames carry the hub's epoch time"
    assert first.recv(0.2) is None and second.recv(0.2) is None

    by_peer = {client.frames_sent: client for client in hub.stats().clients}
    assert by_peer[len(SENT)].frames_queued == 1, "the sender of four frames got only the one reply"
    assert by_peer[1].frames_queued == len(SENT)


def test_channels_are_separate_buses(hub: HubHandle) -> None:
    buses = {name: (connect(hub, name), connect(hub, name)) for name in ("can0", "can1")}
    try:
        wait_for(lambda: hub.stats().clients_per_channel == {"can0": 2, "can1": 2}, what="four clients joined")
        buses["can0"][0].send(can.Message(arbitration_id=0x100, is_extended_id=False, data=b"\x00"))
        buses["can1"][0].send(can.Message(arbitration_id=0x101, is_extended_id=False, data=b"\x01"))
        assert [m.arbitration_id for m in receive(buses["can0"][1], 1)] == [0x100]
        assert [m.arbitration_id for m in receive(buses["can1"][1], 1)] == [0x101]
        assert buses["can0"][1].recv(0.3) is None and buses["can1"][1].recv(0.1) is None
        assert hub.stats().frames_relayed == 2
    finally:
        for sender, receiver in buses.values():
            sender.shutdown()
            receiver.shutdown()


# --- bad input ---------------------------------------------------------------------------------------
MALFORMED = [
    "< send 12345 1 0 >",       # 5 hex digits: neither standard (3) nor extended (8)
    "< send 800 0 >",           # over 0x7FF in a standard ID
    "< send 123 2 1 >",         # LEN says 2, one byte follows
    "< send 123 9 1 2 3 4 5 6 7 8 9 >",  # classic CAN carries at most 8
    "< send 1g3 0 >",           # not hex
    "< send 123 >",             # no LEN
    "< send 123 1  >",          # python-can's writing of a remote frame: LEN without data
]


def test_a_malformed_send_is_counted_and_never_answered(hub: HubHandle) -> None:
    raw = RawClient(hub.port)
    listener = connect(hub)
    try:
        wait_for(lambda: members(hub) == 2, what="both clients joined")
        for text in MALFORMED:
            raw.sock.sendall(text.encode("ascii"))
        # python-can's receive loop would raise on any `< error ... >`, so the next reply must be the echo.
        raw.command("< echo >", b"< echo >")
        wait_for(lambda: hub.stats().frames_rejected == len(MALFORMED), what="every malformed send counted")
        raw.sock.sendall(b"< send 123 1 aa >")
        (relayed,) = receive(listener, 1)
        assert frame_of(relayed) == (0x123, False, b"\xaa", False), "the connection still works"
        assert listener.recv(0.2) is None, "nothing of the malformed sends reached the bus"
        raw.command("< bogus >", b"< error unknown command bogus in rawmode >")
    finally:
        listener.shutdown()
        raw.close()


def test_commands_out_of_order_in_the_handshake_get_an_error(hub: HubHandle) -> None:
    with socket.create_connection(("127.0.0.1", hub.port), timeout=DEADLINE_S) as sock:
        assert sock.recv(256) == b"< hi >"
        sock.sendall(b"< rawmode >")
        assert sock.recv(256) == b"< error rawmode before open >"
        sock.sendall(b"< send 123 0 >")
        assert sock.recv(256) == b"< error send before open >"


# --- overrun -----------------------------------------------------------------------------------------
def test_a_slow_client_loses_frames_counted_while_the_others_get_every_frame() -> None:
    """A client that stops reading fills its socket buffers and its queue, then loses frames (like a CAN
    controller overrun); the sender and a reading client carry on at full pace."""
    total, burst = 4000, 200
    with start_hub_thread(port=0, queue_frames=500, send_buffer_bytes=4096) as hub:
        slow = RawClient(hub.port, receive_buffer=4096)
        sender, reader = connect(hub), connect(hub)
        try:
            wait_for(lambda: members(hub) == 3, what="three clients joined")
            received: list[can.Message] = []
            for start in range(0, total, burst):  # bursts the reader can always take, so its queue never fills
                for n in range(start, start + burst):
                    sender.send(can.Message(arbitration_id=0x181, is_extended_id=False, data=n.to_bytes(2, "little")))
                received += receive(reader, burst)
            assert [int.from_bytes(m.data, "little") for m in received] == list(range(total))

            stats = hub.stats()
            slow_stats = next(c for c in stats.clients if c.peer == slow.address)
            assert slow_stats.frames_dropped > 0
            assert slow_stats.frames_queued + slow_stats.frames_dropped == total
            assert stats.frames_dropped == slow_stats.frames_dropped, "only the slow client lost frames"
        finally:
            sender.shutdown()
            reader.shutdown()
            slow.close()


# --- shutdown ----------------------------------------------------------------------------------------
def test_stop_disconnects_clients_and_frees_the_port() -> None:
    first = start_hub_thread(port=0)
    port = first.port
    raw = RawClient(port)
    wait_for(lambda: first.stats().clients_per_channel == {"can0": 1}, what="the client joined")
    first.stop()
    assert raw.sock.recv(256) == b"", "the client sees the connection end"
    raw.close()
    first.stop()  # a second stop is harmless
    with start_hub_thread(port=port) as second:
        assert second.port == port
        client = RawClient(port)
        client.close()


def test_a_port_in_use_is_a_transport_error_with_a_hint(hub: HubHandle) -> None:
    from drivebench.errors import TransportError

    with pytest.raises(TransportError, match=f"cannot listen on 127.0.0.1:{hub.port}") as info:
        start_hub_thread(port=hub.port)
    assert "--port" in (info.value.hint or "")


# --- bridge ------------------------------------------------------------------------------------------
def test_a_bridge_relays_to_and_from_a_python_can_bus() -> None:
    channel = fresh_channel()
    bridge = BusBridge(f"virtual:{channel}@500000", "can0")
    device = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        with start_hub_thread(port=0, bridges=[bridge]) as hub:
            client = connect(hub)
            try:
                wait_for(lambda: members(hub) == 1, what="the client joined")
                client.send(can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes.fromhex("40C25F00")))
                client.send(can.Message(arbitration_id=0x1ABCDE05, is_extended_id=True, data=b""))
                assert [frame_of(m) for m in receive(device, 2)] == [
                    (0x605, False, bytes.fromhex("40C25F00"), False), (0x1ABCDE05, True, b"", False)]

                device.send(can.Message(arbitration_id=0x585, is_extended_id=False, data=bytes.fromhex("43C25F00")))
                device.send(can.Message(arbitration_id=0x705, is_extended_id=False, is_remote_frame=True, dlc=1))
                device.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=b""))  # CAN_ERR_CRTL
                received = receive(client, 2)
                assert frame_of(received[0]) == (0x585, False, bytes.fromhex("43C25F00"), False)
                assert received[1].is_error_frame and received[1].arbitration_id == 0x004
                assert client.recv(0.2) is None, "a remote frame cannot travel through socketcand"

                stats: HubStats = hub.stats()
                (bridged,) = stats.bridges
                assert (bridged.frames_to_bus, bridged.frames_from_bus, bridged.frames_dropped) == (2, 2, 1)
                assert bridged.spec == f"virtual:{channel}@500000" and bridged.channel == "can0"
            finally:
                client.shutdown()
    finally:
        device.shutdown()


def test_a_bridge_to_a_missing_adapter_stops_the_hub_from_starting() -> None:
    from drivebench.errors import AdapterUnavailable

    with pytest.raises(AdapterUnavailable, match="nosuchcan"):
        start_hub_thread(port=0, bridges=[BusBridge("nosuchcan:can0@500000")])


def test_a_session_bus_on_a_gateway_sends_without_nagle_delays(hub: HubHandle) -> None:
    """``open_bus`` asks python-can for its low-latency socket (``tcp_tune``): an SDO request is a small write
    that must not wait for the previous answer's ACK (benchmarks/RESULTS.md, Request path)."""
    bus = open_bus(BusSpec.parse(f"socketcand:127.0.0.1:{hub.port}/can0"))
    try:
        sock: socket.socket = bus.inner._SocketCanDaemonBus__socket  # type: ignore[attr-defined]  # python-can's own
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    finally:
        bus.shutdown()
