"""Undo of one write from its audit record: the record's old value written back through the one checked write
(:func:`writes.write`: range, selection and read-only checks, the moving-write confirmation, the node's lease,
read-back verify), in the audit log with the origin ``undo <record id>``.

Refused in words when there is nothing sound to write back: the record has no old value (the tool had not read
the parameter before the write), its write failed, or the node is gone or handled with another profile (the same
code could mean another object there).
"""

from __future__ import annotations

import re

from drivebench.errors import Conflict, DriveBenchError, NotFound
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session
from drivebench.services.params import lookup, writes
from drivebench.services.params.values import WriteResult
from drivebench.services.params.write_context import WriteContext
from drivebench.services.users.audit import AuditEntry, entry

UNDO = "undo"
"""The audit origin of an undo: ``undo <id of the undone record>``."""

_SELECTION_SHOWN = re.compile(r"^\s*(-?\d+) = ")


def record(entry_id: int, url: str | None = None) -> AuditEntry:
    found = entry(entry_id, url)
    if found is None:
        raise NotFound(_("No audit record {id}").format(id=entry_id))
    return found


def refusal(session: Session, undone: AuditEntry) -> str | None:
    """Why the record cannot be undone in this session, in words; None when it can."""
    name = f"{undone.ref} ({undone.address})"
    if undone.old_value is None:
        return _("Record {id} has no old value: {ref} had not been read before it was written, so there is no "
                 "value to write back.").format(id=undone.id, ref=name)
    if undone.result in ("failed", "sending"):
        return _("Record {id}: the write of {ref} did not complete ({result}); there is nothing to undo.").format(
            id=undone.id, ref=name, result=_(undone.result))
    node = session.nodes.get(undone.node_id)
    if node is None:
        return _("Record {id}: node {node} is no longer in session {session}.").format(
            id=undone.id, node=undone.node_id, session=session.id)
    profile = node.profile.id if node.profile is not None else None
    if undone.profile is not None and profile != undone.profile:
        return _("Record {id}: node {node} is handled with profile {now} now, not {then} as when {ref} was written; "
                 "the old value is not written back.").format(id=undone.id, node=undone.node_id,
                                                              now=profile or _("(none)"), then=undone.profile,
                                                              ref=name)
    try:
        item = lookup.resolve(node, undone.ref)
    except DriveBenchError as exc:
        return _("Record {id}: {ref} is not a parameter of node {node} now ({why}).").format(
            id=undone.id, ref=name, node=undone.node_id, why=exc.shown_detail())
    if item.address != undone.address:
        return _("Record {id}: {ref} is at {now} in the node's profile now, not {then}; the old value is not "
                 "written back.").format(id=undone.id, ref=undone.ref, now=item.address, then=undone.address)
    return None


def old_value(session: Session, undone: AuditEntry) -> object:
    """The record's old value as :func:`writes.write` takes it (a selection shown ``0 = 500 kbit/s`` by its
    number)."""
    assert undone.old_value is not None
    node = session.node(undone.node_id)
    shown = _SELECTION_SHOWN.match(undone.old_value)
    item = lookup.resolve(node, undone.ref)
    if shown is not None and item.entry.selection:
        return writes.given_value(node, undone.ref, None, int(shown.group(1)))
    return undone.old_value


async def undo(session: Session, undone: AuditEntry, *, ctx: WriteContext) -> WriteResult:
    """Write the record's old value back as ``ctx`` writes (the checked write, verified, logged as ``undo <id>``)."""
    if undone.session_id != session.id:
        raise Conflict(_("Record {id} was written in session {then}, not {now}").format(
            id=undone.id, then=undone.session_id, now=session.id))
    why = refusal(session, undone)
    if why is not None:
        raise Conflict(why)
    return await writes.write(session, undone.node_id, undone.ref, old_value(session, undone),
                                  ctx=ctx.as_origin(f"{UNDO} {undone.id}"))
