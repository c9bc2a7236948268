"""What the services keep for one session, in one container: made when the session opens, closed with it.

The session manager makes it (``SessionManager.open``) and closes it before the bus closes; the services reach
their part through the session (``session.services.monitor`` ...), never through a module-level table.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from drivebench.services import monitor as monitors
from drivebench.services import parameters as params
from drivebench.services.commissioning import Wizard
from drivebench.services.drive_guard import Guard
from drivebench.services.monitor import Monitor
from drivebench.services.node_lease import SessionLeases
from drivebench.services.parameters import SessionParameters, WriteAudit
from drivebench.services.process_data import ProcessData
from drivebench.services.sessions import Session


@dataclass
class SessionServices:
    monitor: Monitor
    parameters: SessionParameters
    wizard: Wizard
    leases: SessionLeases
    process_data: ProcessData
    guard: Guard
    write_audits: list[WriteAudit] = field(default_factory=list)
    """Told about every write the session sends (the server's audit log)."""

    @classmethod
    def open(cls, session: Session, write_audits: list[WriteAudit]) -> SessionServices:
        return cls(monitors.attach(session), params.attach(session), Wizard(), SessionLeases(), ProcessData(session),
                   Guard(session), list(write_audits))

    def close(self, session: Session) -> None:
        """Stop what the services run on the session's bus (SYNC, cyclic RPDOs) and detach the monitor from it."""
        self.process_data.stop_sync()
        for task in self.process_data.cyclic.values():
            task.cancel()
        self.process_data.cyclic.clear()
        session.remove_frame_listener(self.monitor)
