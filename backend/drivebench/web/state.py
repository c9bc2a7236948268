"""What the web app holds while it runs."""

from __future__ import annotations

from dataclasses import dataclass, field

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.session_manager import SessionManager
from drivebench.services.users.sharing import ShareLinks
from drivebench.simulator.ethercat import GatewayServer
from drivebench.simulator.plant import Plant


@dataclass
class AppState:
    registry: ProfileRegistry
    manager: SessionManager
    share_links: ShareLinks = field(default_factory=ShareLinks)
    plants: dict[str, Plant] = field(default_factory=dict)
    """Simulated plants by the id of the session that watches them."""
    gateways: dict[str, GatewayServer] = field(default_factory=dict)
    """Simulated EtherCAT masters' mailbox gateways by the id of the session that reaches them."""
