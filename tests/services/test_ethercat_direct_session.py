"""A session on the direct master (``ethercat:eth1``): the same services as on the mailbox gateway - slave list,
parameters by Lenze code, NMT commands as state changes through the safety guard, the manual's refusal of a PDO
mapping write.

No EtherCAT card and no slave here: pysoem's Master/CdefSlave are stood in by :mod:`tests.protocol.soem_fake`
(the simulator's 8400 motec EtherCAT units behind pysoem's API, pysoem's real exception classes); the session,
services, network and link are the real ones. What was run on what is in the README's EtherCAT table.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, SdoAbortError
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.protocol.ethercat import esm
from drivebench.protocol.ethercat.master import DirectNetwork
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.params import parameters
from drivebench.services.session_manager import SessionServices
from drivebench.simulator.ethercat import SimulatedSlave
from drivebench.transport.ethercat_soem import DirectSpec, SoemLink
from tests.confirming import confirmed_call
from tests.protocol.soem_fake import fake_pysoem
from tests.services.test_ethercat_session import PROFILE, _run
from tests.write_contexts import SERVICE


@contextlib.asynccontextmanager
async def _direct(registry: ProfileRegistry, units: list[SimulatedSlave]) -> AsyncIterator[Session]:
    spec = DirectSpec("eth1")
    network = DirectNetwork(spec, SoemLink(spec, fake_pysoem(units), timeout_s=0.3), sdo_timeout_s=0.3,
                            sdo_retries=1)
    session = Session("direct", "Direct master", spec, network, registry)
    services = SessionServices.open(session, [])
    try:
        await session.scan()
        yield session
    finally:
        services.close(session)
        session.close()


def test_a_direct_master_session_reads_writes_and_changes_states_like_the_gateways(registry: ProfileRegistry
                                                                                   ) -> None:
    profile = registry.get(PROFILE)
    units = [SimulatedSlave(profile, 0, 0, name="Conveyor"), SimulatedSlave(profile, 0, 1, name="Lift")]
    try:
        for unit in units:
            unit.node.power_on()
        _run(_direct_scenario(registry, units))
    finally:
        for unit in units:
            unit.power_off()  # ends the nodes' SDO workers


async def _direct_scenario(registry: ProfileRegistry, units: list[SimulatedSlave]) -> None:
    async with _direct(registry, units) as session:
        assert sorted(session.nodes) == [1, 2] and session.nodes[2].device_name == "Lift"
        assert session.nodes[1].profile is not None and session.nodes[1].profile.id == PROFILE
        assert session.slaves[1].station == 0x1001 and session.nmt_state(1) == ("Pre-Operational", True)
        assert session.bus_state == "active"

        value = await parameters.read(session, 1, "C00039/1")
        assert (value.raw, value.value) == (0x0FA0, pytest.approx(40.0))
        assert (await parameters.write(session, 1, "C00039/1", "55.5", ctx=SERVICE)).verified is True
        assert units[0].store.get(0x5FD8, 1) == 5550 and units[1].store.get(0x5FD8, 1) == 0x0FA0

        with pytest.raises(ConfirmationRequired):
            await drive_guard.nmt(session, NmtCommand.START, 1, ctx=SERVICE)
        await confirmed_call(drive_guard.nmt, session, NmtCommand.START, 1, confirm="1",
                             ctx=SERVICE)  # Pre-Op -> Safe-Op -> Op
        assert session.nmt_state(1) == ("Operational", True) and drive_guard.guard_for(session).armed(1)
        await drive_guard.guard_for(session).trip(1, "test: keep-alive lost")
        assert units[0].state is esm.EsmState.PRE_OPERATIONAL
        await drive_guard.nmt(session, NmtCommand.STOP, 1, ctx=SERVICE)  # EtherCAT: Safe-Operational
        assert session.nmt_state(1) == ("Safe-Operational", True)
        assert units[0].state is esm.EsmState.SAFE_OPERATIONAL
        with pytest.raises(SdoAbortError) as refused:
            await parameters.write(session, 1, "0x1A00.1", 0x5C930110, ctx=SERVICE)
        assert refused.value.abort_text == ("Due to the current device state, data cannot be transferred to the "
                                            "application or stored in the application")
        await drive_guard.nmt(session, NmtCommand.RESET_NODE, 1, ctx=SERVICE)  # through Init back to Pre-Operational
        assert session.nmt_state(1) == ("Pre-Operational", True)
        await parameters.write(session, 1, "0x1A00.1", 0x5C930110, ctx=SERVICE)  # Pre-Operational: accepted
