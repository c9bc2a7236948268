"""Sessions against the simulated demo plant on a virtual bus: open/list/close, scan, NMT, live node state, and
the errors a user sees for bad bus specifications."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, TypeVar

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import AdapterUnavailable, BusSpecError, Conflict, NotFound
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import monitor_for
from drivebench.services.params import node_lease
from drivebench.services.pdos import process_data
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant
from drivebench.transport.bus import BusSpec
from tests.conftest import fresh_channel

T = TypeVar("T")
DEMO_NODES = {3: "siemens-micromaster4-canopen", 5: "lenze-8400-motec-canopen", 7: "generic-cia402-servo",
              12: "lenze-8200-vector-emf2178ib"}


def run(main: Callable[[], Coroutine[Any, Any, T]]) -> T:
    return asyncio.run(main())


async def until(check: Callable[[], object], timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        await asyncio.sleep(0.02)
    raise AssertionError("condition not met in time")


async def with_session(registry: ProfileRegistry, bus: str, work: Callable[[Session], Awaitable[None]]) -> None:
    manager = SessionManager(registry)
    session = await manager.open(bus)
    try:
        await work(session)
    finally:
        await manager.close_all()


def states(session: Session) -> dict[int, str]:
    return {node_id: session.nmt_state(node_id)[0] for node_id in DEMO_NODES}


# --- open, list, close -------------------------------------------------------------------------------
def test_several_sessions_each_with_its_own_network(registry: ProfileRegistry) -> None:
    async def main() -> None:
        manager = SessionManager(registry)
        first = await manager.open(f"virtual:{fresh_channel()}@500000", "Line 1")
        second = await manager.open(f"virtual:{fresh_channel()}@250000", "Line 2")
        third = await manager.open(BusSpec(interface="virtual", channel=fresh_channel(), bitrate=125_000))
        try:
            assert [s.id for s in manager.list()] == [first.id, second.id, third.id]
            assert len({first.id, second.id, third.id}) == 3
            assert first.network is not second.network and first.network.canopen is not second.network.canopen
            assert (first.name, second.spec.bitrate, third.spec.bitrate) == ("Line 1", 250_000, 125_000)
            assert manager.get(second.id) is second
            await manager.close(second.id)
            assert [s.id for s in manager.list()] == [first.id, third.id]
            with pytest.raises(NotFound):
                manager.get(second.id)
            with pytest.raises(NotFound):
                await manager.close(second.id)
        finally:
            await manager.close_all()
        assert manager.list() == []

    run(main)


def test_the_same_bus_cannot_be_opened_twice(registry: ProfileRegistry) -> None:
    async def main() -> None:
        manager = SessionManager(registry)
        bus = f"virtual:{fresh_channel()}@500000"
        first = await manager.open(bus)
        try:
            with pytest.raises(Conflict, match="already open"):
                await manager.open(bus)
            assert manager.list() == [first]
        finally:
            await manager.close_all()

    run(main)


def test_two_sessions_with_the_same_name_get_distinct_ids(registry: ProfileRegistry) -> None:
    async def main() -> None:
        manager = SessionManager(registry)
        try:
            one = await manager.open(f"virtual:{fresh_channel()}", "Line")
            two = await manager.open(f"virtual:{fresh_channel()}", "Line")
            assert one.id == "line" and two.id != one.id
        finally:
            await manager.close_all()

    run(main)


def test_each_session_has_its_own_services_made_at_open_and_closed_with_it(registry: ProfileRegistry) -> None:
    async def main() -> None:
        manager = SessionManager(registry)
        one = await manager.open(f"virtual:{fresh_channel()}@500000", "One")
        two = await manager.open(f"virtual:{fresh_channel()}@500000", "Two")
        try:
            assert set(one.parts) == set(two.parts) and len(one.parts) >= 8
            assert all(one.parts[kind] is not two.parts[kind] for kind in one.parts)
            assert monitor_for(one) is not monitor_for(two)
            assert node_lease.leases(one) is not node_lease.leases(two)
            assert process_data.service(one) is not process_data.service(two)
            others = set(threading.enumerate())
            process_data.service(one).start_sync(10)
            (producer,) = set(threading.enumerate()) - others
            await until(lambda: monitor_for(one).snapshot()["totals"]["frames"] > 0)  # counting from the start
            await manager.close(one.id)
            assert process_data.service(one).sync_period_ms is None
            await until(lambda: not producer.is_alive())  # the SYNC producer stopped with the session
            assert monitor_for(two).snapshot()["totals"]["frames"] == 0  # the other session saw none of it
        finally:
            await manager.close_all()

    run(main)


# --- scan and identity --------------------------------------------------------------------------------
def test_scan_finds_the_demo_nodes_and_identifies_them_by_0x1018(registry: ProfileRegistry, plant: Plant) -> None:
    async def work(session: Session) -> None:
        found = {node.node_id: node for node in await session.scan(0.3)}
        assert sorted(found) == sorted(DEMO_NODES)
        micromaster = found[3]
        assert micromaster.profile is not None and micromaster.profile.id == DEMO_NODES[3]
        assert micromaster.identity["vendor_id"] == micromaster.profile.identity.vendor_id
        for node_id in (5, 12):  # Lenze: vendor 0x3B; the manuals give no product code to tell the drives apart
            assert found[node_id].identity["vendor_id"] == 0x3B
            if found[node_id].profile is None:
                assert "vendor 0x0000003B" in found[node_id].device_name
        assert sorted(session.nodes) == sorted(DEMO_NODES)
        assert session.heartbeat(5).configured_period_s == 0.5, "the scan reads the producer period (0x1017)"

    run(lambda: with_session(registry, str(plant.spec), work))


def test_scan_keeps_the_profiles_a_session_already_has(registry: ProfileRegistry, plant: Plant) -> None:
    async def work(session: Session) -> None:
        for node_id, profile_id in DEMO_NODES.items():
            session.add_node(node_id, profile_id)
        await session.scan(0.3)
        assert {n: node.profile.id if node.profile else None for n, node in session.nodes.items()} == DEMO_NODES
        assert session.nodes[5].identity["vendor_id"] == 0x3B

    run(lambda: with_session(registry, str(plant.spec), work))


def test_scan_of_an_empty_bus_finds_nothing(registry: ProfileRegistry) -> None:
    async def work(session: Session) -> None:
        assert await session.scan(0.1) == []

    run(lambda: with_session(registry, f"virtual:{fresh_channel()}", work))


# --- NMT and node state -------------------------------------------------------------------------------
def test_nmt_broadcast_and_per_node_change_the_heartbeat_state(registry: ProfileRegistry, plant: Plant) -> None:
    async def work(session: Session) -> None:
        for node_id, profile_id in DEMO_NODES.items():
            session.add_node(node_id, profile_id)
        await until(lambda: set(states(session).values()) == {"Pre-operational"})
        assert all(session.nmt_state(n)[1] for n in DEMO_NODES), "the state comes from the heartbeat"
        await session.nmt(NmtCommand.START)
        await until(lambda: set(states(session).values()) == {"Operational"})
        await session.nmt(NmtCommand.STOP, 12)
        await until(lambda: states(session) == {3: "Operational", 5: "Operational", 7: "Operational", 12: "Stopped"})
        await session.nmt(NmtCommand.ENTER_PRE_OPERATIONAL)
        await until(lambda: set(states(session).values()) == {"Pre-operational"})
        bootups = session.heartbeat(5).bootups
        await session.nmt(NmtCommand.RESET_NODE, 5)
        await until(lambda: session.heartbeat(5).bootups == bootups + 1)
        with pytest.raises(NotFound):
            await session.nmt(NmtCommand.START, 99)

    run(lambda: with_session(registry, str(plant.spec), work))


def test_a_silent_node_shows_heartbeat_lost(registry: ProfileRegistry, plant: Plant) -> None:
    async def work(session: Session) -> None:
        session.add_node(5, DEMO_NODES[5])
        session.add_node(12, DEMO_NODES[12])
        # loss is judged against the producer period: measured from two telegrams (or read from 0x1017 by a scan)
        await until(lambda: session.heartbeat(5).expected_period_s() is not None)
        assert session.nmt_state(5) == ("Pre-operational", True)
        await asyncio.to_thread(plant.nodes[5].power_off)
        await until(lambda: session.nmt_state(5)[0] == "Heartbeat lost")
        assert session.heartbeat(5).is_lost()
        assert session.nmt_state(12) == ("Pre-operational", True), "the other node is still alive"

    run(lambda: with_session(registry, str(plant.spec), work))


def test_without_heartbeat_the_state_is_the_last_command(registry: ProfileRegistry) -> None:
    async def work(session: Session) -> None:
        session.add_node(7, None)
        assert session.nmt_state(7) == ("Unknown", False)
        await session.nmt(NmtCommand.START, 7)
        assert session.nmt_state(7) == ("Operational (commanded)", False)

    run(lambda: with_session(registry, f"virtual:{fresh_channel()}", work))


# --- bad bus specifications ----------------------------------------------------------------------------
def _open_error(registry: ProfileRegistry, bus: str | BusSpec) -> AdapterUnavailable | BusSpecError:
    async def main() -> AdapterUnavailable | BusSpecError:
        manager = SessionManager(registry)
        with pytest.raises((AdapterUnavailable, BusSpecError)) as caught:
            await manager.open(bus)
        assert manager.list() == [], "a failed open leaves no session behind"
        return caught.value

    return run(main)


def test_unknown_interface_lists_the_known_ones(registry: ProfileRegistry) -> None:
    error = _open_error(registry, "socketcann:can0@500000")
    assert isinstance(error, AdapterUnavailable)
    assert "socketcann" in error.detail
    assert error.hint is not None and "socketcan" in error.hint and "virtual" in error.hint and "pcan" in error.hint


@pytest.mark.parametrize(("bus", "hint_words"), [
    ("socketcan:can0@500000", "ip link set can0 up"),  # no SocketCAN on this machine
    ("pcan:PCAN_USBBUS1@250000", "PEAK driver"),
    ("kvaser:0@500000", "Kvaser CANlib"),
    ("slcan:/dev/ttyACM9@500000", "serial port"),
])
def test_a_missing_adapter_names_the_interface_and_what_to_check(bus: str, hint_words: str,
                                                                 registry: ProfileRegistry) -> None:
    error = _open_error(registry, bus)
    assert isinstance(error, AdapterUnavailable)
    assert error.detail.startswith(f"Cannot open {bus.split('@')[0]}")
    assert error.hint is not None and hint_words in error.hint


def _closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_an_unreachable_socketcand_gateway_fails_fast_with_host_and_port(registry: ProfileRegistry) -> None:
    """python-can's socketcand client would retry for 10 s; the session answers at once."""
    port = _closed_port()
    started = time.monotonic()
    error = _open_error(registry, f"socketcand:127.0.0.1:{port}/can0")
    assert time.monotonic() - started < 8, "python-can's own retry loop (10 s) was not bypassed"
    assert isinstance(error, AdapterUnavailable)
    assert f"127.0.0.1:{port}" in error.detail
    assert error.hint is not None and f"drivebench hub --port {port}" in error.hint


@pytest.mark.parametrize("text", ["can0", "socketcan", "SocketCAN:can0", "socketcan:can0@fast", ""])
def test_malformed_bus_text_is_a_bus_spec_error(text: str, registry: ProfileRegistry) -> None:
    error = _open_error(registry, text)
    assert isinstance(error, BusSpecError)
    assert "INTERFACE:CHANNEL@BITRATE" in error.detail


def test_a_socketcand_bus_without_port_says_how_to_write_it(registry: ProfileRegistry) -> None:
    error = _open_error(registry, "socketcand:gateway/can0")
    assert isinstance(error, BusSpecError)
    assert "socketcand:HOST:PORT/CHANNEL" in error.detail
