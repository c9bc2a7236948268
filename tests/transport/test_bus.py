"""Bus specifications and opening adapters: any python-can interface, clear errors, observed transmits."""

from __future__ import annotations

import socket

import can
import pytest

from drivebench.errors import AdapterUnavailable, BusSpecError
from drivebench.transport.bus import AdapterLost, BusSpec, BusUnusable, open_bus, rate_of
from tests.conftest import wait_until


@pytest.mark.parametrize(("text", "interface", "channel", "bitrate", "options"), [
    ("socketcan:can0@500000", "socketcan", "can0", 500_000, {}),
    ("pcan:PCAN_USBBUS1@250000", "pcan", "PCAN_USBBUS1", 250_000, {}),
    ("kvaser:0@125000", "kvaser", "0", 125_000, {}),
    ("slcan:/dev/ttyACM0@1000000", "slcan", "/dev/ttyACM0", 1_000_000, {}),
    ("virtual:plant", "virtual", "plant", 500_000, {}),
    ("socketcand:10.1.2.3:29536/can0", "socketcand", "can0", 500_000, {"host": "10.1.2.3", "port": 29536}),
    ("socketcand:gw.line1:29536/can1@250000", "socketcand", "can1", 250_000, {"host": "gw.line1", "port": 29536}),
])
def test_parse(text: str, interface: str, channel: str, bitrate: int, options: dict[str, object]) -> None:
    spec = BusSpec.parse(text)
    assert (spec.interface, spec.channel, spec.bitrate, spec.options) == (interface, channel, bitrate, options)
    assert BusSpec.parse(str(spec)) == spec


@pytest.mark.parametrize("text", ["", "can0", "socketcan", "socketcan:can0@fast", "Socket CAN:can0"])
def test_parse_rejects_with_the_accepted_forms(text: str) -> None:
    with pytest.raises(BusSpecError, match="INTERFACE:CHANNEL@BITRATE"):
        BusSpec.parse(text)


@pytest.mark.parametrize(("text", "host_clock"), [
    ("virtual:x@500000", True), ("socketcan:can0@500000", True), ("socketcand:127.0.0.1:29536/can0", True),
    ("socketcand:localhost:29536/can0", True), ("socketcand:10.1.2.3:29536/can0", False),
    ("pcan:PCAN_USBBUS1@250000", False), ("kvaser:0@500000", False), ("vector:0@500000", False),
    ("slcan:/dev/ttyACM0@500000", False)])
def test_only_buses_that_stamp_in_this_hosts_clock_say_so(text: str, host_clock: bool) -> None:
    """The scope puts a frame at a SYNC by its bus timestamp only where that is this host's time.time()."""
    assert BusSpec.parse(text).stamps_in_host_clock() is host_clock


def test_unknown_interface_lists_the_known_ones() -> None:
    with pytest.raises(AdapterUnavailable, match="Unknown CAN interface 'canfox'") as info:
        open_bus(BusSpec.parse("canfox:0@500000"))
    assert "socketcan" in (info.value.hint or "") and "pcan" in (info.value.hint or "")


def test_missing_socketcan_names_interface_and_what_to_check() -> None:
    with pytest.raises(AdapterUnavailable, match=r"Cannot open socketcan:vcan9@500000") as info:
        open_bus(BusSpec.parse("socketcan:vcan9@500000"))
    assert "ip link set vcan9 up" in (info.value.hint or "")


def test_unreachable_gateway_fails_fast_with_a_hint() -> None:
    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    with pytest.raises(AdapterUnavailable, match=f"Cannot reach the socketcand gateway at 127.0.0.1:{port}") as info:
        open_bus(BusSpec.parse(f"socketcand:127.0.0.1:{port}/can0"))
    assert "drivebench hub" in (info.value.hint or "")


def test_observed_bus_reports_transmitted_frames(channel: str, wire: can.BusABC) -> None:
    bus = open_bus(BusSpec.parse(f"virtual:{channel}"))
    seen: list[can.Message] = []
    bus.add_observer(seen.append)
    try:
        bus.send(can.Message(arbitration_id=0x605, data=bytes([0x40, 0xC2, 0x5F, 0, 0, 0, 0, 0]),
                             is_extended_id=False))
        received = wire.recv(1)
        assert received is not None and received.arbitration_id == 0x605
        assert [m.arbitration_id for m in seen] == [0x605] and seen[0].timestamp > 0
        bus.remove_observer(seen.append)
    finally:
        bus.shutdown()


def test_every_other_bus_on_a_virtual_channel_gets_its_own_copy(channel: str, wire: can.BusABC) -> None:
    # the simulated adapter hands python-can's virtual bus a frame that copies cheaply; what arrives must be what a
    # plain virtual bus delivers: a can.Message of its own, every field kept, data not shared with the sender's
    second = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    bus = open_bus(BusSpec.parse(f"virtual:{channel}"))
    sent = can.Message(arbitration_id=0x1ABCDE, data=bytes(range(8)), is_extended_id=True)
    try:
        bus.send(sent)
        copies = [wire.recv(1), second.recv(1)]
        sent.data[0] = 0xFF
        for copy in copies:
            assert copy is not None and isinstance(copy, can.Message) and copy is not sent
            assert rate_of(copy) == 500_000  # the bit rate it was sent at (issue 32: rates on the virtual bus)
            assert (copy.arbitration_id, copy.is_extended_id, copy.dlc, copy.is_rx) == (0x1ABCDE, True, 8, True)
            assert copy.data == bytearray(range(8)) and copy.timestamp > 0
        assert copies[0].data is not copies[1].data  # type: ignore[union-attr]
    finally:
        bus.shutdown()
        second.shutdown()


def test_a_failing_adapter_is_lost_then_reopened_under_the_same_bus(channel: str, wire: can.BusABC) -> None:
    bus = open_bus(BusSpec.parse(f"virtual:{channel}"))
    changes: list[bool] = []
    bus.watch_link(lambda link: changes.append(link.lost))
    frame = can.Message(arbitration_id=0x605, data=bytes(8), is_extended_id=False)
    try:
        assert bus.adapter is not None
        bus.adapter.unplug()
        with pytest.raises(AdapterLost, match="adapter lost: USB adapter unplugged") as lost:
            bus.send(frame)
        assert isinstance(lost.value, can.CanOperationError)  # canopen and python-can callers see their own error
        assert bus.link.lost and bus.recv(0.05) is None  # the reader waits quietly instead of raising
        with pytest.raises(AdapterLost):
            bus.send(frame)  # at once, without touching the adapter
        assert wait_until(lambda: bus.link.attempts >= 1, 5)
        assert bus.link.attempts >= 1 and "USB adapter unplugged" in (bus.link.last_attempt_error or "")
        bus.adapter.plug_in()
        bus.reconnect_now()
        assert wait_until(lambda: not bus.link.lost, 5)
        assert not bus.link.lost and bus.link.reconnects == 1 and changes == [True, False]
        bus.send(frame)
        received = wire.recv(1)
        assert received is not None and received.arbitration_id == 0x605
    finally:
        bus.shutdown()


def test_a_send_guard_refuses_at_once(channel: str) -> None:
    bus = open_bus(BusSpec.parse(f"virtual:{channel}"))
    bus.send_guard = lambda: "bus-off: nothing is sent until it recovers"
    try:
        with pytest.raises(BusUnusable, match="bus-off"):
            bus.send(can.Message(arbitration_id=0x605, data=bytes(8), is_extended_id=False))
        assert not bus.link.lost
    finally:
        bus.shutdown()


def test_virtual_adapters_hear_only_frames_at_their_bit_rate_and_one_can_be_reopened_at_another(
        channel: str, wire: can.BusABC) -> None:
    """Issue 32: python-can's virtual bus has no bit rate; the simulated adapters have one. A frame reaches the
    adapters at its sender's rate only (and a plain python-can bus, which has none); an adapter reopened at another
    rate under the same object hears that rate from then on."""
    at_500 = open_bus(BusSpec.parse(f"virtual:{channel}@500000"))
    at_250 = open_bus(BusSpec.parse(f"virtual:{channel}@250000"))
    frame = can.Message(arbitration_id=0x123, data=bytes(2), is_extended_id=False)
    try:
        at_500.send(frame)
        assert at_250.recv(0.3) is None
        plain = wire.recv(1)
        assert plain is not None and rate_of(plain) == 500_000
        at_500.reopen_at(250_000)
        assert at_500.spec.bitrate == 250_000 and str(at_500.spec).endswith("@250000")
        at_500.send(frame)
        heard = at_250.recv(1)
        assert heard is not None and rate_of(heard) == 250_000
        wire.send(can.Message(arbitration_id=0x321, data=b"", is_extended_id=False))  # no rate: every adapter hears
        assert at_500.recv(1) is not None and at_250.recv(1) is not None
        assert not at_500.link.lost
    finally:
        at_500.shutdown()
        at_250.shutdown()
