"""The LSS master against LSS slaves written from CiA 305 alone (tests/protocol/cia305_slaves.py), through the real
python-can virtual bus."""

from __future__ import annotations

import time
from collections.abc import Iterator

import can
import canopen
import pytest

from drivebench.protocol.canopen.lss import LssAddress, LssError, LssMaster, LssNoAnswer, timing_index
from tests.conftest import fresh_channel, wait_until
from tests.protocol.cia305_slaves import Cia305Bus, Cia305Device

DEVICES = [(0x3B, 0x8400, 0x10002, 0x0A000001), (0x3B, 0x8400, 0x10002, 0x0A000002),
           (0x06000053, 2, 0x43000205, 77), (0, 0x402001, 0x10000, 0xFFFFFFFF),
           (0x3B, 0x8200, 1, 5), (0x3B, 0x8200, 1, 0x80000005), (0x1234, 0xFFFFFFFF, 0, 0), (0, 0, 0, 1)]


@pytest.fixture
def rig() -> Iterator[tuple[Cia305Bus, LssMaster, canopen.Network]]:
    channel = fresh_channel()
    slaves = Cia305Bus(channel, [Cia305Device(*address) for address in DEVICES])
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.connect()
    master = LssMaster(network, window_s=0.1)
    yield slaves, master, network
    master.close()
    network.disconnect()
    slaves.shutdown()


def test_fastscan_finds_all_eight(rig: tuple[Cia305Bus, LssMaster, canopen.Network]) -> None:
    _slaves, master, _network = rig
    result = master.fastscan()
    assert sorted(address.parts() for address in result.found) == sorted(DEVICES)
    assert master.identify_non_configured()  # found, still without a node ID (waiting in configuration state)
    master.switch_global(configuration=False)
    again = master.fastscan()  # all back in waiting, none configured: all found again
    assert len(again.found) == 8


def test_address_one_device_and_it_boots(rig: tuple[Cia305Bus, LssMaster, canopen.Network]) -> None:
    slaves, master, network = rig
    booted: list[bytes] = []
    network.subscribe(0x700 + 20, lambda cob, data, ts: booted.append(bytes(data)))
    address = LssAddress(*DEVICES[2])
    master.switch_selective(address)
    assert master.inquire_address() == address
    assert master.inquire_node_id() == 0xFF
    with pytest.raises(LssError, match="refused node ID 0: out of range"):
        master.configure_node_id(0)
    master.configure_node_id(20)
    with pytest.raises(LssError, match="not supported"):
        master.configure_bit_timing(5)
    master.configure_bit_timing(timing_index(250_000))
    master.store_configuration()
    master.switch_global(configuration=False)
    assert wait_until(lambda: booted == [b"\x00"])
    assert slaves.devices[2].stored == (20, 3)
    assert master.identify_remote(0x06000053, 2, (0x43000000, 0x43FFFFFF), (0, 100))
    assert not master.identify_remote(0x06000053, 2, (0, 1), (0, 100))
    assert len(master.fastscan().found) == 7  # the addressed one no longer takes part


def test_two_devices_in_configuration_state_are_told_apart_by_their_answers(
        rig: tuple[Cia305Bus, LssMaster, canopen.Network]) -> None:
    _slaves, master, _network = rig
    master.switch_global(configuration=True)
    # eight devices, four vendor IDs: the identical answers merge, four frames come
    with pytest.raises(LssError, match="4 different answers to inquire identity: more than one device"):
        master.inquire_address()
    # identical answers merge: eight devices accepting the same node ID answer with one frame
    master.configure_node_id(30)


def test_no_answer_in_words(rig: tuple[Cia305Bus, LssMaster, canopen.Network]) -> None:
    _slaves, master, _network = rig
    with pytest.raises(LssNoAnswer, match="in LSS waiting state"):
        master.switch_selective(LssAddress(9, 9, 9, 9))
    with pytest.raises(LssNoAnswer, match="no LSS slave answered store configuration"):
        master.store_configuration()


def test_bit_rate_outside_the_table_is_refused_in_words() -> None:
    with pytest.raises(LssError, match="not in the CiA 305 bit timing table"):
        timing_index(100_000)


def test_canopen_fastscan_misses_late_answers_ours_does_not() -> None:
    """A slave that answers 30 ms late: canopen's fastscan, waiting 20 ms, takes each late answer for none and
    finds nothing; ours (the same 20 ms first) re-asks with the full window and finds it."""
    channel = fresh_channel()
    slow = Cia305Bus(channel, [Cia305Device(0x3B, 0x8400, 1, 1234)], answer_delay_s=0.03)
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.connect()
    try:
        network.lss.RESPONSE_TIMEOUT = 0.02
        ok, _ident = network.lss.fast_scan()
        assert not ok
        time.sleep(0.2)
        master = LssMaster(network, window_s=0.2, min_window_s=0.02)
        master.switch_global(configuration=False)
        assert [a.serial for a in master.fastscan().found] == [1234]
    finally:
        network.disconnect()
        slow.shutdown()


class _StallsOnTheFirstProbe(Cia305Bus):
    """A device whose thread gets no CPU for 0.4 s just as the master asks "is any device left?" (a loaded machine):
    its answer to that one request comes 0.4 s late; every other answer in time."""

    def __init__(self, channel: str, devices: list[Cia305Device]) -> None:
        super().__init__(channel, devices)
        self.stalled = False

    def heard(self, msg: can.Message, rate: int | None) -> None:
        data = bytes(msg.data)
        if msg.arbitration_id == 0x7E5 and data[:1] == b"\x51" and data[5:6] == b"\x80" and not self.stalled:
            self.stalled = True
            time.sleep(0.4)
        super().heard(msg, rate)


def test_a_device_whose_answer_to_the_first_probe_comes_late_is_found() -> None:
    """The scan asks "any device without node ID left?" three times before it ends; the third waited five answer
    windows (250 ms at the default 50 ms), so a device stalled 0.4 s on that question was left out of the scan; then
    ten (0.5 s), and a loaded clean-clone run still left it out. Before any answer the third waits timeout_s."""
    channel = fresh_channel()
    slaves = _StallsOnTheFirstProbe(channel, [Cia305Device(0x3B, 0x8400, 1, 1234)])
    network = canopen.Network(can.Bus(interface="virtual", channel=channel))
    network.connect()
    try:
        master = LssMaster(network)
        assert [address.serial for address in master.fastscan().found] == [1234]
        master.switch_global(configuration=False)
    finally:
        network.disconnect()
        slaves.shutdown()
