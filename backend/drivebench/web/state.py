"""What the web app holds while it runs."""

from __future__ import annotations

from dataclasses import dataclass, field

from drivebench.device.loader import ProfileRegistry
from drivebench.services.sessions import SessionManager
from drivebench.services.sharing import ShareLinks
from drivebench.simulator.plant import Plant


@dataclass
class AppState:
    registry: ProfileRegistry
    manager: SessionManager
    share_links: ShareLinks = field(default_factory=ShareLinks)
    plants: dict[str, Plant] = field(default_factory=dict)
    """Simulated plants by the id of the session that watches them."""
