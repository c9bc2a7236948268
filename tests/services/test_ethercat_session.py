"""An EtherCAT session through a simulated master's mailbox gateway on UDP 127.0.0.1: the slave list from the
master's object dictionary, parameters by Lenze code through CoE, the state machine through AL control, and every
fault in words."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Coroutine, Iterator
from typing import Any

import pytest

from drivebench import i18n
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ProtocolError, SdoAbortError, SdoTimeoutError, TransportError
from drivebench.protocol.ethercat import esm
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import monitor_for
from drivebench.services.params import parameters
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from tests.confirming import confirmed_call
from tests.conftest import wait_until
from tests.transport.test_multiprocess import run_outside_playwright
from tests.write_contexts import SERVICE

PROFILE = "lenze-8400-motec-ethercat"


@pytest.fixture
def gateway(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    profile = registry.get(PROFILE)
    server = GatewayServer([SimulatedSlave(profile, 1001, 0, name="Conveyor"),
                            SimulatedSlave(profile, 1002, 1, name="Lift")]).start()
    yield server
    server.stop()


def _run(scenario: Coroutine[Any, Any, None]) -> None:
    run_outside_playwright(lambda: scenario)  # a browser test earlier in the run holds the main thread's loop


@contextlib.asynccontextmanager
async def _open(registry: ProfileRegistry, spec: str) -> AsyncIterator[tuple[SessionManager, Session]]:
    manager = SessionManager(registry, sdo_timeout_s=0.3, sdo_retries=1)
    try:
        yield manager, await manager.open(spec, "EtherCAT line")
    finally:
        await manager.close_all()


def test_slaves_come_from_the_master_with_station_and_state(registry: ProfileRegistry,
                                                             gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            assert sorted(session.nodes) == [1, 2]
            assert session.slaves[1].station == 1001 and session.slaves[2].station == 1002
            assert session.nodes[1].profile is not None and session.nodes[1].profile.id == PROFILE
            assert session.nodes[2].device_name == "Lift"
            assert session.nmt_state(1) == ("Pre-Operational", True)

    _run(scenario())


def test_c00039_reads_40_percent_and_a_write_is_verified(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            value = await parameters.read(session, 1, "C00039/1")
            assert value.raw == 0x0FA0 and value.value == pytest.approx(40.0)
            result = await parameters.write(session, 1, "C00039/1", "55.5", ctx=SERVICE)
            assert result.verified is True
            assert gateway.slaves[1001].store.get(0x5FD8, 1) == 5550
            assert gateway.slaves[1002].store.get(0x5FD8, 1) == 0x0FA0  # the other slave is untouched
            assert session.network.counters(1).requests >= 3  # type: ignore[union-attr]

    _run(scenario())


def test_mapping_write_outside_pre_operational_is_refused_in_the_manuals_words(
        registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            segment = session.ethercat
            assert segment is not None
            await parameters.write(session, 1, "0x1A00.1", 0x5C930110, ctx=SERVICE)  # Pre-Operational: accepted
            info = await asyncio.to_thread(segment.request_state, 1, esm.EsmState.SAFE_OPERATIONAL)
            assert info.state_text == "Safe-Operational"
            with pytest.raises(SdoAbortError) as refused:
                await parameters.write(session, 1, "0x1A00.1", 0x5C930110, ctx=SERVICE)
            assert refused.value.abort_code == 0x08000022
            assert refused.value.abort_text == ("Due to the current device state, data cannot be transferred to the "
                                                "application or stored in the application")

    _run(scenario())


def test_a_refused_state_change_says_the_al_status_code(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            segment = session.ethercat
            assert segment is not None
            with pytest.raises(ProtocolError, match=r"did not change to Bootstrap: Pre-Operational \+ error: "
                                                    r"\"Bootstrap\" status is not supported \(0x0013\)"):
                await asyncio.to_thread(segment.request_state, 2, esm.EsmState.BOOTSTRAP)
            assert gateway.slaves[1002].store.get_ref("C13879") == 1  # bit 0: general bus error
            gateway.slaves[1002].request_state(esm.EsmState.INIT)
            assert gateway.slaves[1002].request_state(esm.EsmState.OPERATIONAL) == 0x0011  # the slave: one step
            await asyncio.to_thread(segment.request_state, 2, esm.EsmState.OPERATIONAL)  # the master steps up
            assert gateway.slaves[1002].state is esm.EsmState.OPERATIONAL
            await asyncio.to_thread(segment.request_state, 2, esm.EsmState.INIT)
            with pytest.raises(SdoTimeoutError, match="station 1002 did not answer"):  # Init: no mailbox
                await parameters.read(session, 2, "C00039/1")

    _run(scenario())


def test_nmt_commands_change_the_ethercat_state_through_the_safety_guard(registry: ProfileRegistry,
                                                                         gateway: GatewayServer) -> None:
    from drivebench.errors import ConfirmationRequired
    from drivebench.protocol.canopen.nmt import NmtCommand
    from drivebench.services.control import drive_guard

    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            with pytest.raises(ConfirmationRequired, match="confirm it with confirm = '1'"):
                await drive_guard.nmt(session, NmtCommand.START, 1, ctx=SERVICE)
            await confirmed_call(drive_guard.nmt, session, NmtCommand.START, 1, confirm="1", ctx=SERVICE)
            assert gateway.slaves[1001].state is esm.EsmState.OPERATIONAL
            assert session.nmt_state(1) == ("Operational", True)
            assert drive_guard.guard_for(session).armed(1)  # kept alive by the page, or stopped
            await drive_guard.guard_for(session).trip(1, "test: keep-alive lost")
            assert gateway.slaves[1001].state is esm.EsmState.PRE_OPERATIONAL
            await drive_guard.nmt(session, NmtCommand.STOP, 1, ctx=SERVICE)
            assert session.nmt_state(1) == ("Safe-Operational", True)

    _run(scenario())


def test_states_changed_elsewhere_are_read_again(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            gateway.slaves[1002].request_state(esm.EsmState.SAFE_OPERATIONAL)  # another master tool did it
            gateway.slaves[1002].request_state(esm.EsmState.BOOTSTRAP)
            assert session.nmt_state(2) == ("Pre-Operational", True)  # what the master said at the scan
            await session.refresh_states(max_age_s=0)
            assert session.nmt_state(2) == ("Safe-Operational + error: \"Bootstrap\" status is not supported "
                                            "(0x0013)", True)
            gateway.stop()
            await session.refresh_states(max_age_s=0)
            assert session.nmt_state(2) == ("Unknown", False)

    _run(scenario())


def test_emergency_of_a_slave_reaches_the_session(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            await parameters.read(session, 2, "C00039/1")  # the gateway learns where to send slave 2's mailbox
            gateway.slaves[1002].raise_fault(0x1000, 0x01, bytes.fromhex("3181BC01"))
            assert await asyncio.to_thread(wait_until, lambda: session.last_emcy(2) is not None)
            event = session.last_emcy(2)
            assert event is not None and event.code == 0x1000 and event.data[:4] == bytes.fromhex("3181BC01")
            assert session.network.counters(2).emergencies == 1  # type: ignore[union-attr]

    _run(scenario())


def test_a_slave_missing_from_the_segment_in_words(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    async def scenario() -> None:
        async with _open(registry, gateway.spec) as (_, session):
            segment = session.ethercat
            assert segment is not None
            segment.stations[3] = 1003  # configured in the master, but not on the wire
            session.add_node(3, PROFILE)
            with pytest.raises(SdoTimeoutError, match=r"station 1003 did not answer .* not on the segment"):
                await parameters.read(session, 3, "C00039/1")

    _run(scenario())


def test_silent_gateway_and_no_direct_master_in_words(registry: ProfileRegistry, gateway: GatewayServer) -> None:
    port = gateway.port
    gateway.stop()

    async def scenario() -> None:
        async with _open(registry, f"ethercat-mbg:127.0.0.1:{port}") as (manager, session):
            assert session.nodes == {}
            assert "Slave list not read" in (session.bus_text or "")
            assert "did not answer" in (session.bus_text or "")
            with i18n.using("de"):  # the link's sentence is worded when shown: the Plant page's and the monitor's
                assert (session.bus_text or "").startswith("Mailbox-Gateway ")
                assert "Slave-Liste nicht gelesen" in (session.bus_text or "")
                assert monitor_for(session).snapshot()["bus_text"].startswith("Mailbox-Gateway ")
            with pytest.raises(TransportError, match=r"pip install 'drivebench\[ethercat\]'|CAP_NET_RAW|network card"):
                await manager.open("ethercat:eth9")

    _run(scenario())
