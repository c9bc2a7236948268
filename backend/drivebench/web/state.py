"""What the web app holds while it runs: one :class:`AppState` (``app.state.drivebench``), reached by routes through
:func:`app_state` or the ``StateDep`` dependency (:mod:`drivebench.web.deps`)."""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from starlette.applications import Starlette

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.params.jobs import JobManager
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage.reachability import RecentProbes
from drivebench.services.users.accounts import Accounts
from drivebench.services.users.sharing import ShareLinks
from drivebench.simulator.ethercat import GatewayServer
from drivebench.simulator.plant import Plant
from drivebench.web.access import Sessions

if TYPE_CHECKING:  # the monitor socket's module reaches this one through the routes' dependencies
    from drivebench.web.monitor_feed import Feed


@dataclass
class AppState:
    registry: ProfileRegistry
    manager: SessionManager
    share_links: ShareLinks = field(default_factory=ShareLinks)
    accounts: Accounts = field(default_factory=Accounts)
    """The users and API tokens as this app read them lately, and the sign-in with its rate limits."""
    cookie_sessions: Sessions = field(default_factory=Sessions)
    """The signer of the session cookies."""
    database_probes: RecentProbes = field(default_factory=RecentProbes)
    """The database's last answers to the health check's probe."""
    plants: dict[str, Plant] = field(default_factory=dict)
    """Simulated plants by the id of the session that watches them."""
    gateways: dict[str, GatewayServer] = field(default_factory=dict)
    """Simulated EtherCAT masters' mailbox gateways by the id of the session that reaches them."""
    jobs: JobManager = field(default_factory=JobManager)
    """The server's jobs: parameter reads, parameter set uploads and downloads."""
    monitor_feeds: dict[str, Feed] = field(default_factory=dict)
    """The monitor websockets' feeds by session id (made when the first client of a session listens)."""
    scope_messages: weakref.WeakKeyDictionary[Any, tuple[tuple[int, int, int], str]] = field(
        default_factory=weakref.WeakKeyDictionary)
    """The scope socket's last ``rows`` message of each running recording, encoded once for every viewer who takes
    the same rows (``web.ws.scope.rows_message``); a recording that is gone takes its entry along."""
    live_sockets: set[Any] = field(default_factory=set)
    """The open websockets (``web.live_access.LiveSocket``, not named here: that module reads this state), each
    re-checked every second and at once after an account change (:mod:`drivebench.web.live_access`)."""


def app_state(app: Starlette) -> AppState:
    """The app's state (made when the app starts)."""
    state: AppState = app.state.drivebench
    return state
