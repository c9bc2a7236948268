"""The transport seam: what a session's network is, and how a bus specification opens one.

A session holds a :data:`Network`, a CAN bus with its canopen network or an EtherCAT segment (behind a mailbox
gateway, or on a network card with the tool as master). Both offer the same SDO clients
(``network.node(id).upload/download`` with the same errors), the emergency monitor (``network.emcy``), the node list
(``network.scan``), and say in words what they do not have (NMT, CAN frames, heartbeat on EtherCAT; AL states on
CAN). Parameters, parameter sets and diagnostics only use that common part.

Bus specifications: ``INTERFACE:CHANNEL@BITRATE`` / ``socketcand:HOST:PORT/CHANNEL`` (CAN),
``ethercat-mbg:HOST[:PORT]`` (a master's mailbox gateway, ETG.8200) and ``ethercat:NIC`` (a direct master on a
network card through pysoem, the ``drivebench[ethercat]`` extra).
"""

from __future__ import annotations

from drivebench.i18n import _
from drivebench.protocol.canopen.network import CanopenNetwork, NodeClient
from drivebench.protocol.ethercat.master import DirectNetwork
from drivebench.protocol.ethercat.network import CoeNodeClient, EthercatNetwork, GatewayNetwork
from drivebench.transport.bus import BusSpec, open_bus
from drivebench.transport.ethercat_gateway import GatewaySpec
from drivebench.transport.ethercat_soem import INSTALL, DirectSpec, load_pysoem, may_use_raw_sockets, open_link

Network = CanopenNetwork | EthercatNetwork
SdoClient = NodeClient | CoeNodeClient
ETHERCAT_INTERFACES = ("ethercat-mbg", "ethercat")
"""What the session form offers next to python-can's interfaces: a master's mailbox gateway, a direct master."""
SessionSpec = BusSpec | GatewaySpec | DirectSpec


def interface_notes() -> dict[str, str]:
    """What the session form says next to an interface that cannot open here (the direct master's needs)."""
    if load_pysoem() is None:
        return {"ethercat": _("direct master: needs {install}").format(install=INSTALL)}
    if not may_use_raw_sockets():
        return {"ethercat": _("direct master: needs root or CAP_NET_RAW")}
    return {}


def parse_spec(text: str) -> SessionSpec:
    cleaned = text.strip()
    if cleaned.startswith("ethercat-mbg:"):
        return GatewaySpec.parse(cleaned)
    if cleaned.startswith("ethercat:"):
        return DirectSpec.parse(cleaned)
    return BusSpec.parse(cleaned)


def open_network(spec: SessionSpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    """Open the bus (blocking: call it in a worker thread)."""
    if isinstance(spec, GatewaySpec):
        return GatewayNetwork(spec, sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)
    if isinstance(spec, DirectSpec):
        return DirectNetwork(spec, open_link(spec, sdo_timeout_s), sdo_timeout_s=sdo_timeout_s,
                             sdo_retries=sdo_retries)
    return CanopenNetwork(open_bus(spec), sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)
