"""The open sessions of this server, each with its services' container (:class:`SessionServices`): built with
their collaborators when the session opens, closed with it.

The container hangs on the session (``session.services``); a service reaches its own part through it, seen through
a Protocol in its own module (``services: MonitorPart = session.opened_services()``, wrapped by each module's accessor:
:func:`~drivebench.services.monitoring.monitor.monitor_for` ...), never through a module-level table: the session
(:mod:`drivebench.services.bus.sessions`, below the services in the layers) names none of them.
"""

from __future__ import annotations

import asyncio
import itertools
import re
from dataclasses import dataclass

from drivebench.errors import Conflict, DriveBenchError, NotFound
from drivebench.i18n import _
from drivebench.services.bus.fieldbus import SessionSpec, open_network, parse_spec
from drivebench.services.bus.sessions import ProfileSource, Session
from drivebench.services.control.commissioning import Wizard, WizardPart
from drivebench.services.control.drive_guard import Guard, GuardPart
from drivebench.services.monitoring import monitor as monitors
from drivebench.services.monitoring.monitor import Monitor, MonitorPart
from drivebench.services.monitoring.recording import Recordings, RecordingsPart
from drivebench.services.monitoring.telegram_counters import CounterHistory, CounterHistoryPart
from drivebench.services.params import session_part
from drivebench.services.params.node_lease import LeasesPart, SessionLeases
from drivebench.services.params.session_part import ParametersPart, SessionParameters
from drivebench.services.params.write_ports import WriteAudit, WriteAudits
from drivebench.services.pdos.process_data import ProcessData, ProcessDataPart


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "bus"


@dataclass
class SessionServices:
    """What the services keep for one session, each part built here with its collaborators (as canopen's
    ``RemoteNode`` holds ``node.sdo``, ``node.pdo``, ``node.nmt``) and closed with the session."""

    guard: Guard
    parameters: SessionParameters
    """Built with the guard's checks on moving writes and the write audits (the server's audit log)."""
    monitor: Monitor
    wizard: Wizard
    leases: SessionLeases
    process_data: ProcessData
    recordings: Recordings
    counter_history: CounterHistory

    @classmethod
    def open(cls, session: Session, write_audits: list[WriteAudit]) -> SessionServices:
        guard = Guard(session)
        services = cls(guard, session_part.attach(session, guard.moving_writes(), WriteAudits(write_audits)),
                       monitors.attach(session), Wizard(), SessionLeases(), ProcessData(session), Recordings(session),
                       CounterHistory())
        session.services = services
        return services

    def close(self, session: Session) -> None:
        """Stop what the services run on the session's bus (SYNC, cyclic RPDOs, a recording, the keep-alive watch)
        and detach the monitor from it."""
        self.process_data.close()
        self.recordings.close()
        self.guard.close()
        self.counter_history.close()
        session.remove_frame_listener(self.monitor)


def views(services: SessionServices) -> tuple[GuardPart, ParametersPart, MonitorPart, WizardPart, LeasesPart,
                                               ProcessDataPart, RecordingsPart, CounterHistoryPart]:
    """The container seen through the view of each service (:meth:`Session.opened_services`): mypy checks here that it
    offers every part a service reaches through the session."""
    return services, services, services, services, services, services, services, services


class SessionManager:
    """The open sessions of this server."""

    def __init__(self, profiles: ProfileSource, *, sdo_timeout_s: float = 0.5, sdo_retries: int = 1,
                 write_audits: list[WriteAudit] | None = None) -> None:
        self.profiles = profiles
        self.write_audits = write_audits or []
        """Told about every write of every session (the server's audit log)."""
        self.sdo_timeout_s = sdo_timeout_s
        self.sdo_retries = sdo_retries
        self._sessions: dict[str, Session] = {}
        self._ids = itertools.count(1)
        self._lock = asyncio.Lock()

    async def open(self, spec: SessionSpec | str, name: str | None = None, *, simulated: bool = False) -> Session:
        bus_spec = parse_spec(spec) if isinstance(spec, str) else spec
        async with self._lock:
            for session in self._sessions.values():
                if str(session.spec) == str(bus_spec):
                    raise Conflict(_("{bus} is already open as session '{session}'").format(bus=bus_spec,
                                                                                          session=session.name))
            network = await asyncio.to_thread(open_network, bus_spec, self.sdo_timeout_s, self.sdo_retries)
            label = name or f"{bus_spec.interface} {bus_spec.channel}".strip()
            session_id = _slug(name or f"{bus_spec.interface}-{bus_spec.channel}")
            if session_id in self._sessions:
                session_id = f"{session_id}-{next(self._ids)}"
            session = Session(session_id, label, bus_spec, network, self.profiles, simulated=simulated)
            SessionServices.open(session, self.write_audits)
            self._sessions[session_id] = session
        if session.network.capabilities.esm:  # the master knows its slaves: list them at once
            try:
                await session.scan()
            except DriveBenchError as exc:
                failure = exc  # the note is worded when shown, in the reader's language
                session.health.notes.append(lambda: _("Slave list not read: {why}").format(
                    why=failure.shown_detail()))
        return session

    def get(self, session_id: str) -> Session:
        session = self._sessions.get(session_id)
        if session is None:
            raise NotFound(_("No open session '{session}'").format(session=session_id))
        return session

    def list(self) -> list[Session]:
        return list(self._sessions.values())

    async def close(self, session_id: str) -> None:
        session = self.get(session_id)
        async with self._lock:
            self._sessions.pop(session_id, None)
        if session.services is not None:
            session.services.close(session)
        await asyncio.to_thread(session.close)

    async def close_all(self) -> None:
        for session_id in list(self._sessions):
            await self.close(session_id)
