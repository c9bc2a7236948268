"""The parameter service's part of a session (:class:`SessionParameters`: SDO settings, the last values read,
the SDO2 state), and where its bus work runs.

Bus work runs in this module's own thread pool (:func:`on_bus`), so a slow node never waits for a free worker
thread; the transfers of a stop (:func:`stop_first`) have a pool of their own and go before every read waiting for
the node.
"""

from __future__ import annotations

import asyncio
import contextlib
import weakref
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

from drivebench.errors import Conflict, OutOfRange
from drivebench.i18n import _
from drivebench.protocol.canopen.heartbeat import HeartbeatStatus
from drivebench.protocol.canopen.network import SdoChannel
from drivebench.services.bus.sessions import Session
from drivebench.services.params.values import ParameterValue
from drivebench.services.params.write_ports import MovingWrites, WriteAudits

T = TypeVar("T")

_BUS_WORK = ThreadPoolExecutor(max_workers=128, thread_name_prefix="sdo")
_STOP_WORK = ThreadPoolExecutor(max_workers=8, thread_name_prefix="sdo-stop")
"""A stop's transfers never queue behind reads for a worker thread."""
_urgent: ContextVar[bool] = ContextVar("drivebench_sdo_urgent", default=False)


@dataclass
class SdoSettings:
    """Per-session SDO behaviour (the REST API and the node page can change it)."""

    timeout_s: float = 0.5
    retries: int = 1
    use_sdo2: bool = True
    """Activate and use a device's second SDO channel for read-all (where its profile has ``sdo_channels``)."""


@dataclass
class NodeChannels:
    """A node's second SDO channel (:mod:`drivebench.services.params.sdo2`)."""

    sdo2: SdoChannel | None = None
    active: bool = False
    note: str | None = None


@dataclass
class SessionParameters:
    """What the parameter service keeps per session: settings, last values read, SDO2 state."""

    session_ref: weakref.ref[Session]
    settings: SdoSettings
    moving_writes: MovingWrites
    """The drive guard's checks on a write that can move the drive (given when the session opens)."""
    write_audits: WriteAudits
    """Told about every write the session sends (the server's audit log)."""
    values: dict[int, dict[str, ParameterValue]] = field(default_factory=dict)
    failures: dict[int, dict[str, str]] = field(default_factory=dict)
    """node -> ref -> why the last read job could not read it (an abort, a timeout, the node silent); a value read
    later clears it."""
    channels: dict[int, NodeChannels] = field(default_factory=dict)

    @property
    def session(self) -> Session:
        session = self.session_ref()
        if session is None:
            raise Conflict(_("The session has been closed"))
        return session

    def remember(self, node_id: int, value: ParameterValue) -> None:
        self.values.setdefault(node_id, {})[value.ref] = value
        self.failures.get(node_id, {}).pop(value.ref, None)

    def not_read(self, node_id: int, ref: str, why: str) -> None:
        self.failures.setdefault(node_id, {})[ref] = why

    def on_heartbeat(self, status: HeartbeatStatus, event: str) -> None:
        """Boot-up: a reset node happened (by us or anyone), so pending resets are done and SDO2 is gone."""
        if event != "bootup":
            return
        session = self.session_ref()
        if session is None:
            return
        node = session.nodes.get(status.node_id)
        if node is not None:
            node.pending_reset.clear()
        state = self.channels.get(status.node_id)
        if state is not None and state.active:
            state.active = False
            client = session.network.nodes.get(status.node_id)
            servers = client.sdo_servers if client is not None else None
            if servers is not None and state.sdo2 in servers.channels:
                servers.channels.remove(state.sdo2)


def attach(session: Session, moving_writes: MovingWrites, write_audits: WriteAudits) -> SessionParameters:
    """The parameter state of a session (made with the session's services when it opens)."""
    network = session.network
    state = SessionParameters(weakref.ref(session), SdoSettings(network.sdo_timeout_s, network.sdo_retries),
                              moving_writes, write_audits)
    if session.heartbeats is not None:  # SDO2 comes back after a boot-up (CAN)
        session.heartbeats.add_callback(state.on_heartbeat)
    return state


class ParametersPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def parameters(self) -> SessionParameters: ...


def service(session: Session) -> SessionParameters:
    services: ParametersPart = session.opened_services()
    return services.parameters


def configure(session: Session, settings: SdoSettings) -> SdoSettings:
    if not 0.01 <= settings.timeout_s <= 30 or not 0 <= settings.retries <= 10:
        raise OutOfRange(_("SDO timeout must be 0.01 ... 30 s and retries 0 ... 10"))
    state = service(session)
    state.settings = settings
    session.network.sdo_timeout_s = settings.timeout_s
    session.network.sdo_retries = settings.retries
    for client in session.network.nodes.values():
        client.configure(settings.timeout_s, settings.retries)
    return settings


def urgent() -> bool:
    """Whether the transfer at hand is one of a stop's (inside :func:`stop_first`)."""
    return _urgent.get()


async def on_bus(work: Callable[[], T]) -> T:
    """``work`` (blocking bus work) in a worker thread: a stop's own pool inside :func:`stop_first`."""
    return await asyncio.get_running_loop().run_in_executor(_STOP_WORK if _urgent.get() else _BUS_WORK, work)


@contextlib.contextmanager
def stop_first(session: Session, node_id: int) -> Iterator[None]:
    """The reads and writes inside stop the drive (quick stop, disable, the guard's trip): they go before every
    transfer waiting for the node (the one on the wire finishes first), and none of those gets in between them
    (:class:`~drivebench.protocol.canopen.sdo_queue.ChannelLock`)."""
    token = _urgent.set(True)
    try:
        with session.client(node_id).stop_first():
            yield
    finally:
        _urgent.reset(token)
