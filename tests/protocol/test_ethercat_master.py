"""The direct master's segment logic (scan, state machine, CoE SDO, emergencies) over pysoem's API.

No EtherCAT card and no slave answering raw frames here: pysoem's Master/CdefSlave are stood in by
:mod:`tests.protocol.soem_fake`, whose slaves are the simulator's 8400 motec EtherCAT units (their real CoE server and
state machine) and which raises pysoem's real exception classes. The link and the network under test are the real
ones (:class:`SoemLink`, :class:`DirectNetwork`); only pysoem's C part is not.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ProtocolError, SdoAbortError, SdoTimeoutError
from drivebench.protocol.ethercat import esm
from drivebench.protocol.ethercat.master import DIRECT_HINT, DirectNetwork
from drivebench.simulator.ethercat import SimulatedSlave
from drivebench.transport.ethercat_soem import DirectSpec, SoemLink
from tests.conftest import wait_until
from tests.protocol.soem_fake import fake_pysoem

PROFILE = "lenze-8400-motec-ethercat"
MANUAL_0x08000022 = ("Due to the current device state, data cannot be transferred to the application or stored in "
                     "the application")


@pytest.fixture
def units(registry: ProfileRegistry) -> Iterator[list[SimulatedSlave]]:
    profile = registry.get(PROFILE)
    found = [SimulatedSlave(profile, 0, 0, name="Conveyor"), SimulatedSlave(profile, 0, 1, name="Lift")]
    try:
        for unit in found:
            unit.node.power_on()  # power only: the master's scan takes it from Init
        yield found
    finally:
        for unit in found:
            unit.power_off()  # ends the node's SDO workers (a test may have powered it off already)


@pytest.fixture
def network(units: list[SimulatedSlave]) -> Iterator[DirectNetwork]:
    spec = DirectSpec.parse("ethercat:eth1")
    segment = DirectNetwork(spec, SoemLink(spec, fake_pysoem(units), timeout_s=0.2), sdo_timeout_s=0.2,
                            sdo_retries=1)
    yield segment
    segment.close()


def test_scan_lists_slaves_by_position_with_station_and_sii_identity(network: DirectNetwork,
                                                                      registry: ProfileRegistry) -> None:
    assert network.scan() == [1, 2]
    identity = registry.get(PROFILE).identity
    first, second = network.slave(1), network.slave(2)
    assert (first.station, first.name, first.vendor_id, first.product_code) == (
        0x1001, "Conveyor", identity.vendor_id, identity.product_code)
    assert (second.station, second.name) == (0x1002, "Lift")
    assert first.state_text == "Pre-Operational" and network.al_state(2) == (2, 0)  # the scan asks for Pre-Op
    assert network.link.master.opened == "eth1"


def test_no_slave_answering_is_said_in_words(units: list[SimulatedSlave], network: DirectNetwork) -> None:
    for unit in units:
        unit.power_off()
    with pytest.raises(ProtocolError, match=r"No EtherCAT slave answered on eth1: check the cable"):
        network.scan()


def test_coe_sdo_reads_and_writes_the_manuals_examples_and_counts(network: DirectNetwork) -> None:
    network.scan()
    client = network.node(1)
    assert client.upload(0x5FD8, 1) == b"\xa0\x0f"  # manual 9.2: C00039/1 = 0x0FA0
    client.download(0x1600, 1, (0x5C930110).to_bytes(4, "little"))  # manual 9.2, allowed in Pre-Operational
    assert client.upload(0x1600, 1) == (0x5C930110).to_bytes(4, "little")
    counters = network.counters(1)
    assert (counters.requests, counters.responses, counters.aborts) == (3, 3, 0)


def test_sdo_abort_from_soem_in_cia301_or_the_profiles_words(network: DirectNetwork,
                                                             registry: ProfileRegistry) -> None:
    network.scan()
    with pytest.raises(SdoAbortError) as plain:
        network.node(1).upload(0x2FFF, 0)
    assert (plain.value.abort_code, plain.value.abort_text) == (
        0x06020000, "Object does not exist in the object dictionary")  # CiA 301's text, not SOEM's
    assert network.counters(1).aborts == 1


def test_state_machine_maps_process_data_refuses_in_the_manuals_words_and_acknowledges(
        units: list[SimulatedSlave], network: DirectNetwork, registry: ProfileRegistry) -> None:
    network.scan()
    texts = registry.get(PROFILE).abort_texts
    assert texts is not None
    info = network.request_state(1, esm.EsmState.SAFE_OPERATIONAL)
    assert info.state_text == "Safe-Operational" and network.link.mapped
    master = network.link.master
    assert wait_until(lambda: master.cycles > 2)  # process data flows while a slave is Safe-Op or higher
    with pytest.raises(SdoAbortError) as refused:
        network.node(1, texts.texts).download(0x1A00, 1, (0x5C930110).to_bytes(4, "little"))
    assert (refused.value.abort_code, refused.value.abort_text) == (0x08000022, MANUAL_0x08000022)

    with pytest.raises(ProtocolError, match=r"^Slave 1 is Safe-Operational: take the slaves to Pre-Operational "
                                            r"before scanning again \(a scan takes every slave to Init\)\.$"):
        network.scan()

    network.request_state(2, esm.EsmState.INIT)
    assert network.request_state(2, esm.EsmState.OPERATIONAL).state_text == "Operational"  # one step at a time
    network.request_state(2, esm.EsmState.INIT)
    units[1].request_state(esm.EsmState.SAFE_OPERATIONAL)  # a slave refusing a jump (0x0011), as a bad master asks
    assert network.al_state(2) == (esm.EsmState.INIT | esm.ERROR_FLAG, 0x0011)  # registers 0x0130 and 0x0134
    assert network.slave(2).state_text == "Init + error: Invalid status change requested (0x0011)"
    assert network.request_state(2, esm.EsmState.PRE_OPERATIONAL).state_text == "Pre-Operational"  # acknowledged

    network.request_state(1, esm.EsmState.PRE_OPERATIONAL)
    assert not network.link.cyclic.is_set() and not network.link.mapped  # mapped anew on the next way up
    with pytest.raises(ProtocolError, match="Bootstrap"):
        network.request_state(1, esm.EsmState.BOOTSTRAP)


def test_silent_slave_times_out_in_words_after_its_retries(units: list[SimulatedSlave],
                                                           network: DirectNetwork) -> None:
    network.scan()
    network.request_state(2, esm.EsmState.INIT)  # no mailbox in Init
    with pytest.raises(SdoTimeoutError) as silent:
        network.node(2).upload(0x5FD8, 1)
    assert str(silent.value) == ("Slave at station 4098 on eth1 did not answer the mailbox request for 0x5FD8sub1 "
                                 "within 0.2 s: not in Pre-Operational or higher, not on the segment any more, "
                                 "or slow")
    assert silent.value.hint == DIRECT_HINT
    assert network.counters(2).timeouts == 2  # one retry


def test_emergency_read_from_the_mailbox_reaches_the_emcy_monitor(units: list[SimulatedSlave],
                                                                  network: DirectNetwork) -> None:
    network.scan()
    units[1].raise_fault(0x3210, 0x05, b"\x01\x02\x03\x04\x05")
    with network.link.lock:
        network.link.poll_mailboxes()
    event = network.emcy.last(2)
    assert event is not None and (event.code, event.register) == (0x3210, 0x05)
    assert network.counters(2).emergencies == 1 and network.emcy.last(1) is None


def test_a_slave_lost_from_the_segment_in_words(units: list[SimulatedSlave], network: DirectNetwork) -> None:
    network.scan()
    units[0].power_off()
    with pytest.raises(ProtocolError) as lost:
        network.al_state(1)
    assert str(lost.value) == ("The slave at position 1 on eth1 did not answer the read of register 0x0130: lost "
                               "from the segment (cable, power)?")
    with pytest.raises(SdoTimeoutError, match=r"^Slave at station 4097 on eth1 did not answer"):
        network.node(1).upload(0x5FD8, 1)


def test_mailbox_and_packet_errors_from_soem_in_words(network: DirectNetwork) -> None:
    import pysoem

    network.scan()
    slave = network.link.slaves[0]
    refusals = iter([pysoem.MailboxError(1, 0x0004, "The service is not supported"), pysoem.PacketError(1, 1)])

    def refuse(*args: object) -> bytes:
        raise next(refusals)

    slave.sdo_read = refuse
    with pytest.raises(ProtocolError) as mailbox:
        network.node(1).upload(0x5FD8, 1)
    assert str(mailbox.value) == ("Slave at position 1, 0x5FD8sub1: the slave refused the mailbox request: The service "
                                  "is not supported (mailbox error 4)")
    with pytest.raises(ProtocolError, match=r"^Slave at position 1, 0x5FD8sub1: mailbox packet error: Unexpected "
                                            r"frame returned$"):
        network.node(1).upload(0x5FD8, 1)
    assert (network.counters(1).requests, network.counters(1).responses) == (2, 2)
