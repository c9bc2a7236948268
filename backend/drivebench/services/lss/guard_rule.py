"""The safety rule of the LSS steps that reach every device on the bus (switch state global, activate bit timing,
NMT reset communication, and fastscan, which ends with a switch state global): a confirmation that names ``all``
and the values sent (the confirmation contract: 428 with ``confirm_node`` "all"), and a refusal in words while any
node of the session is armed or its status word says enabled."""

from __future__ import annotations

import contextlib

from drivebench.errors import Conflict, DriveBenchError
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_control import describe
from drivebench.services.control.drive_guard import guard_for, read_word, require_confirmation
from drivebench.services.control.drive_words import family_of
from drivebench.services.params.write_context import Values, WriteContext

EVERY_DEVICE = "all nodes on this bus"


async def moving_nodes(session: Session) -> list[int]:
    """The session's nodes that are armed, or whose status word reads enabled (a node that cannot be read now
    is not counted: it is off the bus or has no drive control word)."""
    guard = guard_for(session)
    moving = {node_id for node_id in session.nodes if guard.armed(node_id)}
    for node in list(session.nodes.values()):
        fam = family_of(node.catalog)
        if fam is None or node.node_id in moving:
            continue
        with contextlib.suppress(DriveBenchError):
            if describe(fam, await read_word(session, node.node_id, fam.status_ref))[2]:
                moving.add(node.node_id)
    return sorted(moving)


async def admit_global(session: Session, what: str, values: Values, ctx: WriteContext) -> None:
    """Refused while a node is enabled or armed (409); else the confirmation naming all nodes (428)."""
    moving = await moving_nodes(session)
    if moving:
        raise Conflict(_("{what} reaches every device on the bus: refused while node {nodes} is enabled or armed. "
                         "Disable or stop it first (Control tab, or NMT pre-operational).").format(
            what=what, nodes=", ".join(str(node) for node in moving)))
    require_confirmation(ctx.confirmation, None, what, {"reaches": EVERY_DEVICE, **values})
