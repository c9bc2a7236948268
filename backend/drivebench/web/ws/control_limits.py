"""How many control-panel websockets a node and a user may have open (issue 27 item 7): a crowd of viewers must not
take the server's attention from the panel that drives the node.

Each node of a session accepts :attr:`~drivebench.config.Settings.control_panels_per_node` panels, each user
:attr:`~drivebench.config.Settings.control_panels_per_user` in the session (without sign-in, the name in
``X-DriveBench-User`` or the local user). The panel that holds the node, armed or by its write lease, is never
refused and counts against nobody. A refused socket is told why in words (an ``error`` message, then close code
:data:`TOO_MANY`).
"""

from __future__ import annotations

import weakref
from collections import Counter
from dataclasses import dataclass, field
from typing import TypeVar

from drivebench.config import settings
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_guard import Panel, guard_for
from drivebench.services.params import node_lease

TOO_MANY = 4429
_Key = TypeVar("_Key", int, str)


@dataclass
class _Open:
    per_node: Counter[int] = field(default_factory=Counter)
    per_user: Counter[str] = field(default_factory=Counter)


_OPEN: weakref.WeakKeyDictionary[Session, _Open] = weakref.WeakKeyDictionary()


def close_reason(text: str) -> str:
    """``text`` cut to what a websocket close frame carries (123 bytes of UTF-8)."""
    return text.encode()[:123].decode(errors="ignore")


def holds(session: Session, node_id: int, panel: Panel) -> bool:
    """The panel holds the node: it armed it, or it has the node's write lease."""
    holder = guard_for(session).holder(node_id)
    if holder is not None and holder.panel.key == panel.key:
        return True
    lease = node_lease.leases(session).current(node_id)
    return lease is not None and lease.writer.client == panel.key


class Refused(Exception):
    """The socket is not let in; ``str(exc)`` says why, in the reader's language."""


@dataclass
class Seat:
    """An admitted panel's place, given back with :meth:`leave` when its socket closes."""

    session: Session
    node_id: int
    user: str
    counted: bool

    def leave(self) -> None:
        counts = _OPEN.get(self.session)
        if not self.counted or counts is None:
            return
        self.counted = False
        _down(counts.per_node, self.node_id)
        _down(counts.per_user, self.user)


def _down(counter: Counter[_Key], key: _Key) -> None:
    counter[key] -= 1
    if counter[key] <= 0:
        del counter[key]


def admit(session: Session, node_id: int, panel: Panel, user: str) -> Seat:
    """The panel's place among the node's and the user's sockets; :class:`Refused` when there is none."""
    if holds(session, node_id, panel):
        return Seat(session, node_id, user, counted=False)
    counts = _OPEN.setdefault(session, _Open())
    if counts.per_node[node_id] >= settings.control_panels_per_node:
        raise Refused(_("Node {node} already has {count} control panels open, the most it takes: close one "
                        "first (the panel holding the drive is always let in).").format(
            node=node_id, count=counts.per_node[node_id]))
    if counts.per_user[user] >= settings.control_panels_per_user:
        raise Refused(_("{user} already has {count} control panels open in this session, the most one user may: "
                        "close one of them first.").format(user=user, count=counts.per_user[user]))
    counts.per_node[node_id] += 1
    counts.per_user[user] += 1
    return Seat(session, node_id, user, counted=True)
