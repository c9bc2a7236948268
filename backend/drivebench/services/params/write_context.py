"""What a write is checked against, as one value every write takes: who sends it (the audit log's user and origin),
from which panel (the drive guard's holder of an armed node), as which writer (the node's write lease), with which
confirmation (a moving write's ``confirm`` / ``confirm_values``).

The web layer builds it from the request (``web/safety.write_context``); a service passes it down to every call that
can write (:func:`writes.write`, :func:`writes.send_logged`, :func:`device_commands.command`,
:func:`node_lease.writing` ...), none of which has a default for it: a write that has no context cannot be written.
The guard's own stops (keep-alive lost, a panel closed) run with :meth:`WriteContext.guard_stop`, which no lease
refuses and which confirms nothing: it can send what stops a drive, never a value that can move one.

The write path, where each input is read:

* ``writer``: :func:`node_lease.writing` (take, renew, hold the node's lease; ``None``: only checked);
* ``panel``, ``confirmation``, ``confirmed``, ``cleared``: :func:`drive_guard.confirm_moving` /
  :func:`drive_guard.admit_moving_write` through the session's :class:`parameters.MovingWrites`;
* ``user``, ``origin``: the audit log's row (:class:`parameters.WriteAttempt`);
* ``stops``: :func:`node_lease.writing` lets it through whoever holds the node.
"""

from __future__ import annotations

import getpass
from dataclasses import dataclass, replace

from drivebench.i18n import N_, Text


def _local_user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (containers)
        return "local"


LOCAL_USER = _local_user()
"""The audit log's user where no one signed in (no login configured)."""

Values = dict[str, object]
"""What a moving action will send, as the server builds it from the request it is about to execute: each object
(``"0x60FF Target velocity [rpm]"``) or setting (``"NMT"``) and its value, with its unit in the name where the user
sees one. A confirmation repeats it (``confirm_values``)."""


@dataclass(frozen=True)
class Panel:
    """Who sends a command: one control panel (browser tab) or one API client. ``key`` identifies it, ``who`` is
    what the other panels are shown."""

    key: str
    who: str
    """Shown to the other panels in their language (a :class:`~drivebench.i18n.Text`)."""


SERVICE_PANEL = Panel("service", Text(N_("a DriveBench service call")))


@dataclass(frozen=True)
class Confirmation:
    """What a request carries to confirm a moving action: the node it names and the values it saw."""

    node: object
    values: object = None


@dataclass(frozen=True)
class Writer:
    name: str
    """The principal's name (shown to the others)."""
    client: str
    """One browser tab (``panel:<tab id>``) or one API client (``client:<host>``)."""
    where: str = N_("the API")
    """Where the writes come from, as the others are shown it ("Parameters tab")."""

    def same(self, other: Writer) -> bool:
        return self.name == other.name and self.client == other.client


GUARD_ORIGIN = "control"
"""The audit log's origin of the guard's and the control panel's own writes."""


@dataclass(frozen=True)
class WriteContext:
    """The safety inputs of a write (see the module's text). Built by :meth:`request`, :meth:`internal` or
    :meth:`guard_stop`; narrowed with the methods below, never changed in place."""

    user: str
    origin: str
    panel: Panel
    writer: Writer | None
    """The lease holder it writes as; None takes no lease (refused while someone else holds the node)."""
    confirmation: Confirmation | None
    confirmed: Values | None
    """Values a batch or download already confirmed as a whole (each of its writes then sends some of them)."""
    cleared: bool
    """The caller (the control panel) confirmed and armed what it writes: the guard asks nothing more."""
    stops: bool
    """It stops a drive: no lease refuses it (any station may stop a machine)."""

    @classmethod
    def request(cls, *, user: str, origin: str, panel: Panel, writer: Writer | None,
                confirmation: Confirmation | None) -> WriteContext:
        """A request's (or a job's it starts): its user, panel, writer and confirmation."""
        return cls(user, origin, panel, writer, confirmation, None, False, False)

    @classmethod
    def internal(cls, *, user: str, origin: str) -> WriteContext:
        """A service's own writes without a request: no lease taken, nothing confirmed (a moving value: 428)."""
        return cls(user, origin, SERVICE_PANEL, None, None, None, False, False)

    @classmethod
    def guard_stop(cls, *, user: str = LOCAL_USER) -> WriteContext:
        """The guard's own stop (keep-alive lost, a panel closed): never refused by a lease, and it confirms
        nothing, so only values that stop the drive get through."""
        return cls(user, GUARD_ORIGIN, SERVICE_PANEL, None, None, None, False, True)

    def as_origin(self, origin: str, *, user: str | None = None) -> WriteContext:
        """The same writer, logged with ``origin`` (and as ``user``: a set download names who it is for)."""
        return replace(self, origin=origin, user=user or self.user)

    def confirming(self, confirm: object) -> WriteContext:
        """With the confirmation the request's body carries (it wins over the header's); a bare node id confirms no
        values."""
        if confirm is None or confirm is False:
            return self
        return replace(self, confirmation=confirm if isinstance(confirm, Confirmation) else Confirmation(confirm))

    def with_confirmed(self, confirmed: Values) -> WriteContext:
        return replace(self, confirmed=confirmed)

    def cleared_by_caller(self) -> WriteContext:
        """Writes the caller confirmed and armed itself (the control panel), logged with the origin ``control``."""
        return replace(self, cleared=True, origin=GUARD_ORIGIN)

    def stopping(self) -> WriteContext:
        """The same writes, stopping a drive: no lease refuses them."""
        return replace(self, stops=True)


READ_ALL_ORIGIN = "read-all"
"""The audit log's origin of the writes a read-all sends (switching a node's second SDO channel on)."""
