"""The transport seam: what a session's network is, and how a bus specification opens one.

A session holds a :data:`Network` (a :class:`~drivebench.protocol.fieldbus.Fieldbus`): a CAN bus with its canopen
network or an EtherCAT segment (behind a mailbox gateway, or on a network card with the tool as master). Both offer
the same SDO clients (``network.node(id).upload/download`` with the same errors), the emergency monitor
(``network.emcy``), the node list (``network.scan``), and say what they have in ``network.capabilities`` (NMT, CAN
frames, heartbeat on CAN; AL states on EtherCAT). Which class opens which specification is
:data:`~drivebench.protocol.bus_kinds.BUS_KINDS`.

Bus specifications: ``INTERFACE:CHANNEL@BITRATE`` / ``socketcand:HOST:PORT/CHANNEL`` (CAN),
``ethercat-mbg:HOST[:PORT]`` (a master's mailbox gateway, ETG.8200) and ``ethercat:NIC`` (a direct master on a
network card through pysoem, the ``drivebench[ethercat]`` extra).
"""

from __future__ import annotations

from drivebench.i18n import _
from drivebench.protocol.bus_kinds import Network, SdoClient, SessionSpec, open_network, parse_spec
from drivebench.transport.ethercat_soem import INSTALL, load_pysoem, may_use_raw_sockets

__all__ = ["ETHERCAT_INTERFACES", "Network", "SdoClient", "SessionSpec", "interface_notes", "open_network",
           "parse_spec"]
ETHERCAT_INTERFACES = ("ethercat-mbg", "ethercat")
"""What the session form offers next to python-can's interfaces: a master's mailbox gateway, a direct master."""


def interface_notes() -> dict[str, str]:
    """What the session form says next to an interface that cannot open here (the direct master's needs)."""
    if load_pysoem() is None:
        return {"ethercat": _("direct master: needs {install}").format(install=INSTALL)}
    if not may_use_raw_sockets():
        return {"ethercat": _("direct master: needs root or CAP_NET_RAW")}
    return {}
