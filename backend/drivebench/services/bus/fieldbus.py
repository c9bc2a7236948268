"""The transport seam: what a session's network is, and how a bus specification opens one.

A session holds a :data:`Network`, a CAN bus with its canopen network or an EtherCAT segment behind a mailbox
gateway. Both offer the same SDO clients (``network.node(id).upload/download`` with the same errors), the emergency
monitor (``network.emcy``), the node list (``network.scan``), and say in words what they do not have (NMT, CAN frames,
heartbeat on EtherCAT; AL states on CAN). Parameters, parameter sets and diagnostics only use that common part.

Bus specifications: ``INTERFACE:CHANNEL@BITRATE`` / ``socketcand:HOST:PORT/CHANNEL`` (CAN),
``ethercat-mbg:HOST[:PORT]`` (a master's mailbox gateway, ETG.8200) and ``ethercat:NIC`` (a direct master on a
network card through pysoem, the ``drivebench[ethercat]`` extra).
"""

from __future__ import annotations

import importlib.util
import os
import re
from dataclasses import dataclass

from drivebench.errors import BusSpecError, TransportError
from drivebench.protocol.ethercat_network import CoeNodeClient, EthercatNetwork
from drivebench.protocol.network import CanopenNetwork, NodeClient
from drivebench.transport.bus import BusSpec, open_bus
from drivebench.transport.ethercat_gateway import GatewaySpec

Network = CanopenNetwork | EthercatNetwork
SdoClient = NodeClient | CoeNodeClient
_DIRECT_RE = re.compile(r"^ethercat:(?P<nic>[A-Za-z0-9_.:-]{1,32})$")
CAP_NET_RAW = 13
ETHERCAT_INTERFACES = ("ethercat-mbg", "ethercat")
"""What the session form offers next to python-can's interfaces: a master's mailbox gateway, a direct master."""


@dataclass(frozen=True)
class DirectSpec:
    """``ethercat:eth1``: the tool as EtherCAT master on a network card of its own."""

    nic: str

    interface = "ethercat"
    bitrate = 100_000_000

    @property
    def channel(self) -> str:
        return self.nic

    def __str__(self) -> str:
        return f"ethercat:{self.nic}"


SessionSpec = BusSpec | GatewaySpec | DirectSpec


def parse_spec(text: str) -> SessionSpec:
    cleaned = text.strip()
    if cleaned.startswith("ethercat-mbg:"):
        return GatewaySpec.parse(cleaned)
    if cleaned.startswith("ethercat:"):
        match = _DIRECT_RE.match(cleaned)
        if not match:
            raise BusSpecError(f"'{text}' is not a network card: write ethercat:NIC, e.g. ethercat:eth1")
        return DirectSpec(match["nic"])
    return BusSpec.parse(cleaned)


def _may_use_raw_sockets() -> bool:
    if os.geteuid() == 0:
        return True
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("CapEff:"):
                    return bool(int(line.split()[1], 16) >> CAP_NET_RAW & 1)
    except OSError:
        pass
    return False


def direct_master_refusal(spec: DirectSpec) -> str | None:
    """Why a direct master on ``spec.nic`` cannot run here, in words; None if it could."""
    if importlib.util.find_spec("pysoem") is None:
        return ("The direct EtherCAT master needs pysoem: install DriveBench with its extra "
                "(pip install 'drivebench[ethercat]'), or reach the slaves through a master's mailbox gateway "
                "(ethercat-mbg:HOST).")
    if not _may_use_raw_sockets():
        return (f"The direct EtherCAT master sends raw Ethernet frames on {spec.nic}: run DriveBench as root or give "
                "its Python CAP_NET_RAW (setcap cap_net_raw+ep), or use a master's mailbox gateway "
                "(ethercat-mbg:HOST).")
    if not os.path.exists(f"/sys/class/net/{spec.nic}"):
        return f"This computer has no network card '{spec.nic}' (see ip link)."
    return None


def open_network(spec: SessionSpec, sdo_timeout_s: float, sdo_retries: int) -> Network:
    """Open the bus (blocking: call it in a worker thread)."""
    if isinstance(spec, GatewaySpec):
        return EthercatNetwork(spec, sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)
    if isinstance(spec, DirectSpec):
        refusal = direct_master_refusal(spec)
        raise TransportError(refusal or f"The direct EtherCAT master on {spec.nic} is not built yet in this "
                                            "version; use a master's mailbox gateway (ethercat-mbg:HOST).")
    return CanopenNetwork(open_bus(spec), sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)
