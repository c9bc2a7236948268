"""NMT through the safety guard, shared by the sessions API, the Plant page and the PDO page: the request (start
needs a confirmation; ``keepalive: false`` is for admins, with a reason, logged) and the send."""

from __future__ import annotations

import logging
from typing import Any, Literal

from fastapi import Request
from pydantic import BaseModel, Field

from drivebench.errors import AccessDenied, InvalidValue
from drivebench.i18n import N_, _
from drivebench.protocol.canopen.nmt import COMMAND_BY_NAME, NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.lss.guard_rule import admit_global
from drivebench.services.params.write_context import WriteContext
from drivebench.services.users.principals import Role
from drivebench.web.identity import principal_of
from drivebench.web.safety import confirmation

log = logging.getLogger(__name__)

RESETS = {NmtCommand.RESET_NODE: N_("NMT reset node of all nodes"),
          NmtCommand.RESET_COMMUNICATION: N_("NMT reset communication of all nodes")}
"""The broadcasts that need the all-nodes confirmation and are refused while a node is enabled or armed."""
NmtName = Literal["start", "stop", "pre-operational", "reset-node", "reset-communication"]


class NodeNmtRequest(BaseModel):
    command: NmtName
    confirm: str | int | None = Field(None, description="Start only: the node id (or 'all' for the broadcast), "
                                                        "else 428; or the X-DriveBench-Confirm header")
    confirm_values: dict[str, Any] | None = Field(None, description="Start only: the values the 428 named "
                                                                    "(confirm_values), repeated; or the header "
                                                                    "X-DriveBench-Confirm-Values")
    keepalive: bool = Field(True, description="Start only: false starts without the keep-alive guard (admins, "
                                              "with a reason)")
    keepalive_s: float = Field(drive_guard.KEEPALIVE_TIMEOUT_S, ge=0.5, le=drive_guard.MAX_KEEPALIVE_S,
                               description="Start only: stop the started nodes when no keep-alive came for this long")
    reason: str | None = Field(None, max_length=200, description="Why keepalive is false (logged)")


class NmtRequest(NodeNmtRequest):
    node_id: int = Field(0, ge=0, le=127, description="0 = all nodes (broadcast)")


async def send_nmt(request: Request, session: Session, body: NodeNmtRequest, node_id: int,
                   panel: drive_guard.Panel, ctx: WriteContext) -> None:
    """NMT through the safety guard (shared with the Plant and PDO pages)."""
    command = COMMAND_BY_NAME[body.command]
    if command is NmtCommand.START and not body.keepalive:
        principal = principal_of(request)
        if not principal.may(Role.ADMIN):
            raise AccessDenied(_("Starting a node without the keep-alive guard is for admins only."))
        if not (body.reason or "").strip():
            raise InvalidValue(_("Say why the node runs without the keep-alive guard (reason)."))
        log.warning("NMT start of node %s without keep-alive by %s: %s", node_id or "all", principal.name,
                    body.reason)
    confirm = confirmation(request, body.confirm, body.confirm_values)
    if node_id == 0 and command in RESETS:
        # A broadcast reset reaches every device on the bus, as LSS's global steps do (CiA 305/301): the same rule.
        await admit_global(session, _(RESETS[command]), {"NMT": body.command}, ctx.confirming(confirm))
    await drive_guard.nmt(session, command, node_id, panel, ctx=ctx, confirm=confirm, keepalive=body.keepalive,
                          timeout_s=body.keepalive_s)
