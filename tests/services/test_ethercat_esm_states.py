"""Which EtherCAT states a slave has comes from its profile's ``ethercat`` section: the 8400 motec EtherCAT unit has
no Bootstrap (manual §7.3: AL status code 0x0013), a device whose profile lists Bootstrap is taken there and back,
both through a simulated master's mailbox gateway on UDP 127.0.0.1."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest

from drivebench.device.profiles.ethercat_section import EthercatSection
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import SdoTimeoutError
from drivebench.protocol.ethercat import esm
from drivebench.protocol.ethercat.esm import EsmState
from drivebench.services.params import parameters
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from tests.services.test_ethercat_session import PROFILE, _open, _run

ALL_STATES = ["Init", "Pre-Operational", "Bootstrap", "Safe-Operational", "Operational"]


@pytest.fixture
def line(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    shipped = registry.get(PROFILE)
    with_bootstrap = shipped.model_copy(update={"ethercat": EthercatSection(esm_states=ALL_STATES)})
    server = GatewayServer([SimulatedSlave(shipped, 1001, 0, name="8400 motec"),
                            SimulatedSlave(with_bootstrap, 1002, 1, name="With bootstrap")]).start()
    yield server
    server.stop()


def test_the_shipped_profile_says_the_unit_has_no_bootstrap(registry: ProfileRegistry) -> None:
    section = registry.get(PROFILE).ethercat
    assert section is not None and EsmState.BOOTSTRAP not in section.states
    assert section.states == esm.MANDATORY_STATES and "0x0013" in (section.source or "")


def test_bootstrap_is_refused_by_the_8400_and_reached_by_a_device_whose_profile_has_it(
        registry: ProfileRegistry, line: GatewayServer) -> None:
    without, with_bootstrap = line.slaves[1001], line.slaves[1002]

    async def scenario() -> None:
        async with _open(registry, line.spec) as (_, session):
            segment = session.ethercat
            assert segment is not None
            assert without.request_state(EsmState.BOOTSTRAP) == 0x0013  # the master's request: test_ethercat_session
            assert without.state is EsmState.PRE_OPERATIONAL

            info = await asyncio.to_thread(segment.request_state, 2, EsmState.BOOTSTRAP)  # the master: via Init
            assert info.state_text == "Bootstrap" and with_bootstrap.state is EsmState.BOOTSTRAP
            with pytest.raises(SdoTimeoutError, match="station 1002 did not answer"):  # Bootstrap: FoE, no CoE
                await parameters.read(session, 2, "C00039/1")
            assert with_bootstrap.request_state(EsmState.PRE_OPERATIONAL) == 0x0011  # out of Bootstrap: to Init only
            info = await asyncio.to_thread(segment.request_state, 2, EsmState.PRE_OPERATIONAL)
            assert info.state_text == "Pre-Operational"
            assert (await parameters.read(session, 2, "C00039/1")).raw == 0x0FA0
            assert with_bootstrap.request_state(EsmState.BOOTSTRAP) == 0x0011  # into Bootstrap: from Init only

    _run(scenario())


@pytest.mark.parametrize(("current", "target", "supported", "code"), [
    (EsmState.INIT, EsmState.BOOTSTRAP, esm.MANDATORY_STATES, 0x0013),
    (EsmState.PRE_OPERATIONAL, EsmState.BOOTSTRAP, esm.MANDATORY_STATES, 0x0013),
    (EsmState.INIT, EsmState.BOOTSTRAP, frozenset(EsmState), None),
    (EsmState.PRE_OPERATIONAL, EsmState.BOOTSTRAP, frozenset(EsmState), 0x0011),
    (EsmState.BOOTSTRAP, EsmState.INIT, frozenset(EsmState), None),
    (EsmState.BOOTSTRAP, EsmState.OPERATIONAL, frozenset(EsmState), 0x0011),
    (EsmState.INIT, EsmState.SAFE_OPERATIONAL, esm.MANDATORY_STATES, 0x0011),
    (EsmState.OPERATIONAL, EsmState.INIT, esm.MANDATORY_STATES, None),
    (EsmState.PRE_OPERATIONAL, 5, esm.MANDATORY_STATES, 0x0012),
])
def test_the_al_status_code_of_each_refused_change_is_etg_1000_6s(
        current: EsmState, target: int, supported: frozenset[EsmState], code: int | None) -> None:
    assert esm.transition_refusal(current, target, supported) == code
