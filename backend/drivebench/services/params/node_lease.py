"""Per-node write lease: one writer at a time per (session, node), so two engineers never interleave writes.

A writer is a principal's name plus a client (one browser tab or one API client). The first write to a node takes
its lease; the same writer may then write freely, and every write renews it. Another writer is refused (409, with
who holds the node, since when, from where and when the lease expires) until the holder releases it or stays silent
for :data:`LEASE_TTL_S`. An operation in progress (a parameter-set download) keeps the lease for as long as it runs.
An admin may break a lease (logged). A browser tab's leases end when its last page closes (its keep-alive socket,
:meth:`SessionLeases.client_closed`); the same principal in another tab or script takes over a lease whose client is
not connected (it is the same engineer), never one of a tab still open.

Who writes is the :class:`~drivebench.services.params.write_context.WriteContext` every write carries (its
``writer``); a context without one (a service's own writes) takes no lease but is still refused while someone else
holds the node. Stopping a drive (quick stop, the guard's trip: a context that ``stops``) is never refused.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from typing import Concatenate, ParamSpec, Protocol, TypeVar

from drivebench.errors import Conflict, NotFound
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session
from drivebench.services.params.write_context import WriteContext, Writer

__all__ = ["LEASE_TTL_S", "Lease", "NodeLeased", "SessionLeases", "Writer", "leased", "leases", "writing"]

LEASE_TTL_S = 30.0
log = logging.getLogger(__name__)


@dataclass
class Lease:
    writer: Writer
    since: float  # unix time
    renewed: float  # monotonic
    active: int = 0  # operations in progress

    def expires_in(self, now: float | None = None) -> float:
        if self.active:
            return LEASE_TTL_S
        return max(0.0, self.renewed + LEASE_TTL_S - (time.monotonic() if now is None else now))

    def expired(self) -> bool:
        return not self.active and self.expires_in() <= 0

    def text(self, node_id: int) -> str:
        clock = time.strftime("%H:%M", time.localtime(self.since))
        values = {"node": node_id, "name": self.writer.name, "clock": clock, "where": _(self.writer.where)}
        if self.active:
            return _("Node {node} is being written by {name} (since {clock}, {where}); writes are refused until "
                     "{name} finishes until the operation under way ends.").format(**values)
        return _("Node {node} is being written by {name} (since {clock}, {where}); writes are refused until {name} "
                 "finishes or the lease expires in {seconds} s.").format(**values, seconds=f"{self.expires_in():.0f}")


class NodeLeased(Conflict):
    title = N_("Node is being written by someone else")

    def __init__(self, node_id: int, lease: Lease) -> None:
        super().__init__(lease.text(node_id), hint=N_("An admin may break the lease (DELETE .../lease?force=true)."))
        self.node_id = node_id
        self.lease = lease

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "node": self.node_id, "holder": self.lease.writer.name,
                "holder_where": self.lease.writer.where,
                "since": time.strftime("%H:%M:%S", time.localtime(self.lease.since)),
                "expires_in_s": round(self.lease.expires_in(), 1)}


@dataclass
class SessionLeases:
    leases: dict[int, Lease] = field(default_factory=dict)
    connected: dict[str, int] = field(default_factory=dict)
    """Open pages (keep-alive sockets) per client."""
    lock: threading.Lock = field(default_factory=threading.Lock)

    def _yields_to(self, lease: Lease, writer: Writer) -> bool:
        """The same engineer from another client, while the holding client has no page open and nothing under way."""
        return (lease.writer.name == writer.name and not lease.active
                and not self.connected.get(lease.writer.client))

    def current(self, node_id: int) -> Lease | None:
        with self.lock:
            lease = self.leases.get(node_id)
            if lease is not None and lease.expired():
                del self.leases[node_id]
                return None
            return lease

    def acquire(self, node_id: int, writer: Writer, *, hold: bool = False) -> Lease:
        """Take or renew the lease; ``hold`` also counts one operation in progress (undo with :meth:`done`)."""
        with self.lock:
            lease = self.leases.get(node_id)
            if (lease is not None and not lease.expired() and not lease.writer.same(writer)
                    and not self._yields_to(lease, writer)):
                raise NodeLeased(node_id, lease)
            if lease is None or not lease.writer.same(writer) or lease.expired():
                lease = self.leases[node_id] = Lease(writer, time.time(), time.monotonic())
            lease.renewed = time.monotonic()
            if writer.where != lease.writer.where:
                lease.writer = writer  # the same tab moved on (Parameters -> PDO)
            if hold:
                lease.active += 1
            return lease

    def done(self, node_id: int, writer: Writer) -> None:
        with self.lock:
            lease = self.leases.get(node_id)
            if lease is not None and lease.writer.same(writer):
                lease.active = max(0, lease.active - 1)
                lease.renewed = time.monotonic()

    def check(self, node_id: int) -> None:
        """Refuse a write without a writer while someone holds the node."""
        lease = self.current(node_id)
        if lease is not None:
            raise NodeLeased(node_id, lease)

    def renew(self, node_id: int, client: str) -> bool:
        with self.lock:
            lease = self.leases.get(node_id)
            if lease is None or lease.writer.client != client or lease.expired():
                return False
            lease.renewed = time.monotonic()
            return True

    def release(self, node_id: int, writer: Writer) -> bool:
        with self.lock:
            lease = self.leases.get(node_id)
            if lease is None or not lease.writer.same(writer):
                return False
            del self.leases[node_id]
            return True

    def client_opened(self, client: str) -> None:
        with self.lock:
            self.connected[client] = self.connected.get(client, 0) + 1

    def client_closed(self, client: str) -> list[int]:
        """A page of ``client`` closed; with its last one, its leases end (not one of an operation under way)."""
        with self.lock:
            left = self.connected.get(client, 1) - 1
            if left > 0:
                self.connected[client] = left
                return []
            self.connected.pop(client, None)
            ended = [node for node, lease in self.leases.items() if lease.writer.client == client and not lease.active]
            for node in ended:
                del self.leases[node]
            return ended

    def break_lease(self, node_id: int, by: str) -> Lease:
        with self.lock:
            lease = self.leases.pop(node_id, None)
        if lease is None:
            raise NotFound(_("Node {node} has no write lease.").format(node=node_id))
        log.warning("write lease of node %s held by %s (%s, %s) broken by %s", node_id, lease.writer.name,
                    lease.writer.client, lease.writer.where, by)
        return lease


class LeasesPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def leases(self) -> SessionLeases: ...


def leases(session: Session) -> SessionLeases:
    services: LeasesPart = session.opened_services()
    return services.leases


@contextlib.contextmanager
def writing(session: Session, node_id: int, ctx: WriteContext) -> Iterator[None]:
    """Around one write or one operation on the node: takes (or checks) the lease for ``ctx``'s writer and holds it
    while inside; a context that stops a drive passes."""
    if ctx.stops:
        yield
        return
    writer = ctx.writer
    table = leases(session)
    if writer is None:
        table.check(node_id)
        yield
        return
    table.acquire(node_id, writer, hold=True)
    try:
        yield
    finally:
        table.done(node_id, writer)


P = ParamSpec("P")
R = TypeVar("R")


def leased(write: Callable[Concatenate[Session, int, WriteContext, P], Awaitable[R]]
           ) -> Callable[Concatenate[Session, int, WriteContext, P], Awaitable[R]]:
    """A service coroutine ``(session, node_id, ctx, ...)`` that writes to the node runs inside :func:`writing`."""
    @functools.wraps(write)
    async def under_lease(session: Session, node_id: int, ctx: WriteContext, /, *args: P.args,
                          **kwargs: P.kwargs) -> R:
        with writing(session, node_id, ctx):
            return await write(session, node_id, ctx, *args, **kwargs)
    return under_lease
