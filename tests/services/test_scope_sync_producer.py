"""The scope's SYNC producer on a real virtual bus: which SYNC a frame's bus timestamp falls after, and the
timestamps it does not trust (another clock: the newest SYNC sent is used then)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import can
import pytest

from drivebench.services.scope import sync_producer
from drivebench.services.scope.sync_producer import SyncProducer
from tests.conftest import fresh_channel, wait_until


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    channel = fresh_channel()
    sender = can.Bus(interface="virtual", channel=channel)
    wire = can.Bus(interface="virtual", channel=channel)
    yield sender, wire
    sender.shutdown()
    wire.shutdown()


def _sent(buses: tuple[can.BusABC, can.BusABC], period_s: float, count: int) -> tuple[SyncProducer, list[float]]:
    """A producer that sent at least ``count`` SYNCs, and the bus timestamps of every SYNC the wire got."""
    sender, wire = buses
    producer = SyncProducer(lambda: sender.send(can.Message(arbitration_id=0x080, is_extended_id=False)), period_s)
    producer.start()
    try:
        assert wait_until(lambda: producer.count >= count, 30)
    finally:
        producer.stop()
    syncs = []
    while (msg := wire.recv(0.2)) is not None:
        syncs.append(msg.timestamp)
    assert len(syncs) == producer.count
    return producer, syncs


def test_a_frame_stamped_by_the_bus_is_put_at_the_last_sync_sent_before_it(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    producer, syncs = _sent(buses, 0.005, 5)
    now = time.time()
    # the virtual bus stamps a SYNC inside its send, after the producer took its time and before it takes the next
    # one's: a frame with a SYNC's own timestamp is put at that SYNC, however late it is taken
    assert [producer.stamp_at(stamp, now) for stamp in syncs] == list(range(len(syncs)))
    assert producer.stamp() == len(syncs) - 1
    # not plausible in time.time()'s clock: later than its receive, before the recording, none (0.0)
    assert producer.stamp_at(now + 1, now) is None
    assert producer.stamp_at(syncs[0] - 60, now) is None
    assert producer.stamp_at(0.0, now) is None


def test_a_long_recording_keeps_the_newest_send_times_and_still_numbers_them(
        buses: tuple[can.BusABC, can.BusABC], monkeypatch: pytest.MonkeyPatch) -> None:
    """The send times are kept for the newest SYNCs only (a recording may run for hours at 1 ms): after the oldest
    were let go, a frame's timestamp is still put at the right SYNC number, and one from before them is not trusted."""
    monkeypatch.setattr(sync_producer, "KEPT_SEND_TIMES", 4)
    producer, syncs = _sent(buses, 0.002, 20)
    now = time.time()
    assert producer.stamp_at(syncs[-1], now) == len(syncs) - 1
    assert producer.stamp_at(syncs[-4], now) == len(syncs) - 4  # at least the newest four are kept
    assert producer.stamp_at(syncs[0], now) is None  # let go: the newest SYNC sent is used then
