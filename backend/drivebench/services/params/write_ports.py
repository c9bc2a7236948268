"""What the session gives the writes from above when it opens: the audit log's listeners (:class:`WriteAudits`)
and the drive guard's checks on a write that can move the drive (:class:`MovingWrites`), so the parameter service
needs nothing above it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.scaling import ScaledValue
from drivebench.services.bus.sessions import Session
from drivebench.services.params.values import ParameterValue, WriteResult
from drivebench.services.params.write_context import WriteContext


@dataclass(frozen=True)
class WriteAttempt:
    """A write about to be sent: what the tool last read there (``old``, None if never read) and the new value."""

    session: Session
    node_id: int
    item: Item
    old: ParameterValue | None
    new: ScaledValue
    ctx: WriteContext
    """Who sends it and from where (the audit row's user and origin)."""


class WriteAudit(Protocol):
    """Told about every write :func:`~drivebench.services.params.writes.write` sends: before sending, and with the
    outcome (the audit log)."""

    async def sending(self, attempt: WriteAttempt) -> object: ...

    async def done(self, token: object, result: WriteResult | None, error: BaseException | None) -> None: ...


class WriteAudits(list[WriteAudit]):
    """The session's :class:`WriteAudit` listeners (:attr:`SessionParameters.write_audits`)."""


@dataclass(frozen=True)
class MovingWrites:
    """How :func:`~drivebench.services.params.writes.write` lets a write that can move the drive through: the drive
    guard's checks, given to the session when it opens (:meth:`drive_guard.Guard.moving_writes`)."""

    admit: Callable[[WriteContext, int, str, dict[str, object]], None]
    """The write's context, node id, what is written, the values sent (:func:`sent_values`): refused without the
    context's confirmation naming the node and repeating the values; arms the keep-alive for its panel."""
    stopped: Callable[[WriteContext, int], None]
    """The write's context, node id: a control word that stops the drive was written."""
    confirm: Callable[[WriteContext, int, str, dict[str, object]], WriteContext]
    """The context, node id, what will be written, the values: refused without the confirmation naming the node
    and repeating the values, nothing armed yet (a batch checks this before its first write); the context its writes
    then carry (with these values confirmed)."""
