"""The fieldbus seam (issue 29): a bus specification's prefix picks the network class, the network says what it has
in its capabilities, and the services ask those, never the class. On a real virtual CAN bus and a simulated
EtherCAT master's mailbox gateway on UDP."""

from __future__ import annotations

import ast
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivebench import i18n
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ProtocolError
from drivebench.protocol.bus_kinds import BUS_KINDS, Network, open_network, parse_spec
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.emcy import EmcyEvent
from drivebench.protocol.ethercat.network import master_of
from drivebench.protocol.fieldbus import CAN_BUS, ETHERCAT
from drivebench.simulator.ethercat import GatewayServer, SimulatedSlave
from tests.conftest import wait_until

PACKAGE = Path(__file__).resolve().parents[2] / "backend" / "drivebench"
NETWORK_CLASSES = {"CanopenNetwork", "EthercatNetwork", "GatewayNetwork", "DirectNetwork"}
CLIENT_CLASSES = {"NodeClient", "CoeNodeClient", "CoeSdoClient"}


@pytest.fixture
def gateway(registry: ProfileRegistry) -> Iterator[GatewayServer]:
    server = GatewayServer([SimulatedSlave(registry.get("lenze-8400-motec-ethercat"), 1001, 0)]).start()
    yield server
    server.stop()


@pytest.fixture
def can_network(channel: str) -> Iterator[Network]:
    network = open_network(parse_spec(f"virtual:{channel}@500000"), 0.3, 0)
    yield network
    network.close()


@pytest.fixture
def segment(gateway: GatewayServer) -> Iterator[Network]:
    network = open_network(parse_spec(gateway.spec), 0.3, 0)
    yield network
    network.close()


def test_the_prefix_picks_the_class_as_python_can_picks_an_interface() -> None:
    assert [kind.prefix for kind in BUS_KINDS] == ["ethercat-mbg:", "ethercat:", ""]
    assert type(parse_spec("ethercat-mbg:127.0.0.1:6000")).__name__ == "GatewaySpec"
    assert type(parse_spec(" ethercat:eth1 ")).__name__ == "DirectSpec"
    assert type(parse_spec("virtual:x@500000")).__name__ == "BusSpec"


def test_a_can_bus_has_frames_nmt_and_heartbeat(can_network: Network) -> None:
    assert can_network.capabilities == CAN_BUS
    assert CAN_BUS.nmt and CAN_BUS.heartbeat and CAN_BUS.guarding and CAN_BUS.frames and not CAN_BUS.esm
    assert frames_of(can_network).spec == can_network.spec
    assert master_of(can_network) is None


def test_an_ethercat_segment_offers_no_imitation_of_can(segment: Network) -> None:
    """No dummy heartbeat or guarding monitor, no frame sender that refuses: the capabilities say what is missing,
    and a service that needs frames is refused in words by :func:`frames_of`."""
    assert segment.capabilities == ETHERCAT
    assert not (ETHERCAT.nmt or ETHERCAT.heartbeat or ETHERCAT.guarding or ETHERCAT.frames)
    for imitation in ("heartbeat", "guarding", "send", "send_nmt", "add_listener", "remove_listener"):
        assert not hasattr(segment, imitation), imitation
    assert master_of(segment) is segment
    with i18n.using("en"), pytest.raises(ProtocolError) as refused:
        frames_of(segment)
    assert "EtherCAT has no CAN identifiers" in str(refused.value) and str(segment.spec) in str(refused.value)


def test_a_coe_emergency_is_recorded_as_an_event(gateway: GatewayServer, segment: Network) -> None:
    """The slave's CoE emergency reaches the emergency monitor's callbacks as the record both buses share."""
    seen: list[EmcyEvent] = []
    arrived = threading.Event()
    segment.emcy.add_callback(lambda event: (seen.append(event), arrived.set()))
    assert segment.scan() == [1]
    segment.node(1).upload(0x1000, 0)  # the gateway learns where to send the slave's mailbox
    gateway.slaves[1001].raise_fault(0x3210, 0x05, bytes.fromhex("0102030405"))
    assert arrived.wait(10)
    assert wait_until(lambda: segment.emcy.last(1) is not None)
    event = seen[0]
    assert (event.node_id, event.code, event.register, event.data) == (1, 0x3210, 0x05, bytes.fromhex("0102030405"))
    assert segment.emcy.last(1) == event


def _isinstance_on(path: Path, classes: set[str]) -> list[int]:
    lines = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance" \
                and len(node.args) == 2:
            names = {part.id if isinstance(part, ast.Name) else part.attr
                     for part in ast.walk(node.args[1]) if isinstance(part, ast.Name | ast.Attribute)}
            if names & classes:
                lines.append(node.lineno)
    return lines


def test_no_code_asks_a_network_its_class() -> None:
    """Services, pages and protocol code ask ``network.capabilities``; only the table that opens the buses
    (protocol/bus_kinds.py) knows the classes."""
    found = {str(path.relative_to(PACKAGE)): lines for path in sorted(PACKAGE.rglob("*.py"))
             if (lines := _isinstance_on(path, NETWORK_CLASSES))}
    assert found == {}


def test_no_service_asks_an_sdo_client_its_class() -> None:
    """A node's SDO client says what it offers beyond upload and download (``fast_path``, ``sdo_servers``,
    ``sdo_information``); services and the web ask that, never which class the client is."""
    found = {str(path.relative_to(PACKAGE)): lines for scope in ("services", "web")
             for path in sorted((PACKAGE / scope).rglob("*.py")) if (lines := _isinstance_on(path, CLIENT_CLASSES))}
    assert found == {}


def test_a_client_declares_what_it_offers_beyond_sdo(can_network: Network, segment: Network) -> None:
    """A CAN node's client reads on the event loop and adds SDO channels; a CoE slave's asks the SDO information
    service; neither pretends to have what the other has."""
    assert segment.scan() == [1]
    can_client, coe_client = can_network.node(5), segment.node(1)
    assert (can_client.fast_path, can_client.sdo_servers, can_client.sdo_information) == (can_client, can_client,
                                                                                           None)
    assert (coe_client.fast_path, coe_client.sdo_servers, coe_client.sdo_information) == (None, None, coe_client)
