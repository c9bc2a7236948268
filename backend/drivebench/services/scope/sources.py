"""The one place that chooses the source of a recording, and what starting it moves.

Today every recording polls (SDO on CAN, CoE on EtherCAT). Sampling by PDO plugs in here: it returns its source
where the nodes allow it and names, in :func:`moving_steps`, the nodes it must start (NMT) or the SYNC it produces,
which the recording's start then has confirmed like the drive control panel (polling moves nothing).
"""

from __future__ import annotations

from drivebench.i18n import N_
from drivebench.services.bus.sessions import Session
from drivebench.services.params.write_context import Values
from drivebench.services.scope.poll import PollScopeSource
from drivebench.services.scope.source import ScopeChannel, ScopeSource

MovingStep = tuple[int, str, Values]
"""(node id; what it does, in words; the values it sends) of one moving-class step."""


def open_source(session: Session, channels: list[ScopeChannel], period_s: float) -> ScopeSource:
    return PollScopeSource(session, channels, period_s)


def moving_steps(source: ScopeSource) -> list[MovingStep]:
    """What starting ``source`` moves (a source that starts nodes or a SYNC producer says so in ``moving``)."""
    steps: list[MovingStep] = list(getattr(source, "moving", []))
    return steps


SOURCE_NAMES = {"pdo": N_("sampling by PDO"), "sdo-poll": N_("SDO polling"), "coe-poll": N_("CoE polling")}
"""How the page names a source (translated where shown)."""
