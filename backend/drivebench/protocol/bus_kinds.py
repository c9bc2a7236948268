"""Which class opens a bus specification, by its prefix (as python-can picks a bus class by interface name):
``ethercat-mbg:`` a master's mailbox gateway, ``ethercat:`` the direct master on a network card, anything else a CAN
interface of python-can's. The one place that knows the network classes; the rest of the tool holds a
:class:`~drivebench.protocol.fieldbus.Fieldbus` and asks its capabilities."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from drivebench.protocol.canopen.network import CanopenNetwork, NodeClient
from drivebench.protocol.ethercat.master import DirectNetwork
from drivebench.protocol.ethercat.network import CoeNodeClient, GatewayNetwork
from drivebench.protocol.fieldbus import Fieldbus
from drivebench.transport.bus import BusSpec, open_bus
from drivebench.transport.ethercat_gateway import GatewaySpec
from drivebench.transport.ethercat_soem import DirectSpec, open_link

SdoClient = NodeClient | CoeNodeClient
"""A node's SDO client on any bus: the same methods and errors."""
Network = Fieldbus[SdoClient]
SessionSpec = BusSpec | GatewaySpec | DirectSpec


@dataclass(frozen=True)
class BusKind:
    prefix: str
    """What a specification starts with ("" = python-can's interfaces, asked last)."""
    spec: type[Any]
    parse: Callable[[str], SessionSpec]
    open: Callable[[Any, float, int], Network]
    """(spec, SDO timeout s, SDO retries) -> the opened network (blocking: call it in a worker thread)."""


def _gateway(spec: GatewaySpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    return GatewayNetwork(spec, sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)


def _direct(spec: DirectSpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    return DirectNetwork(spec, open_link(spec, sdo_timeout_s), sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)


def _can(spec: BusSpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    return CanopenNetwork(open_bus(spec), sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)


BUS_KINDS = (
    BusKind("ethercat-mbg:", GatewaySpec, GatewaySpec.parse, _gateway),
    BusKind("ethercat:", DirectSpec, DirectSpec.parse, _direct),
    BusKind("", BusSpec, BusSpec.parse, _can),
)


def parse_spec(text: str) -> SessionSpec:
    cleaned = text.strip()
    return next(kind for kind in BUS_KINDS if cleaned.startswith(kind.prefix)).parse(cleaned)


def open_network(spec: SessionSpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    """Open the bus (blocking: call it in a worker thread)."""
    kind = next(kind for kind in BUS_KINDS if type(spec) is kind.spec)
    return kind.open(spec, sdo_timeout_s, sdo_retries)
