"""The Control tab of the Node screen: the drive's state machine drawn with the current state highlighted, every
control and status bit named, transitions, setpoint, jog, modes, live actual values and the guided commissioning.

The page is rendered once (``node/control_body.html``); control.js then keeps it live over
``/ws/sessions/{session}/nodes/{node}/control`` (whose messages are also the keep-alive) and sends the commands
to the JSON API under ``/api/sessions/{session}/nodes/{node}/control``.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.errors import DriveBenchError
from drivebench.i18n import _
from drivebench.services.control import commissioning, drive_control, motion
from drivebench.services.control.drive_words import Family, family_of
from drivebench.services.monitoring import fault_words
from drivebench.services.scope.channels import panel_channels
from drivebench.web.access_policy import rule_for
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.identity import principal_of
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
UI = "/ui/sessions/{session_id}/nodes/{node_id}/control"
BOX_W, BOX_H, GAP_X, GAP_Y, PAD = 190, 42, 110, 30, 16
PAD_LEFT = 96  # room for the labels of the left (downward) lane
CONTROL_RULE = rule_for("POST", "/api/sessions/{session_id}/nodes/{node_id}/control/commands/{command}")


def refused_because(request: Request) -> str | None:
    """Why this user may watch the drive but not control it (None: may control)."""
    principal = principal_of(request)
    if principal.may(CONTROL_RULE.role):
        return None
    return _("{what} needs the {role} role; you are signed in as {name} ({own_role}), so this panel only "
             "watches.").format(what=_(CONTROL_RULE.what), role=CONTROL_RULE.role.label, name=principal.name,
                                own_role=principal.role.label)


def _diagram(fam: Family) -> dict[str, Any]:
    """Box and arrow coordinates of the state machine (SVG units)."""
    pos = {box.key: (PAD_LEFT + box.col * (BOX_W + GAP_X), PAD + box.row * (BOX_H + GAP_Y)) for box in fam.states}
    boxes = [{"key": box.key, "label": fam.shown(box.label), "x": pos[box.key][0], "y": pos[box.key][1],
              "enabled": box.enabled, "fault": box.fault} for box in fam.states]
    arrows = []
    for arrow in fam.section.arrows:
        (sx, sy), (tx, ty) = pos[arrow.from_state], pos[arrow.to_state]
        if sx == tx:  # vertical: two lanes so up and down arrows do not overlap
            down = ty > sy
            x = sx + BOX_W / 2 + (-30 if down else 30)
            x1, x2 = x, x
            y1, y2 = float(sy + BOX_H if down else sy), float(ty if down else ty + BOX_H)
            label_x, label_y, anchor = x + (-6 if down else 6), (y1 + y2) / 2 + 4, "end" if down else "start"
        else:
            right = tx > sx
            x1, x2 = (float(sx + BOX_W), float(tx)) if right else (float(sx), float(tx + BOX_W))
            y1, y2 = sy + BOX_H / 2, ty + BOX_H / 2
            label_x, label_y, anchor = (x1 + x2) / 2, (y1 + y2) / 2 - 6, "middle"
        arrows.append({"x1": x1, "y1": y1, "x2": x2, "y2": y2, "label": fam.shown(arrow.label), "lx": label_x,
                       "ly": label_y, "anchor": anchor})
    width = max(x for x, _ in pos.values()) + BOX_W + PAD
    height = max(y for _, y in pos.values()) + BOX_H + PAD
    return {"boxes": boxes, "arrows": arrows, "width": width, "height": height, "box_w": BOX_W, "box_h": BOX_H}


@router.get(UI, response_class=HTMLResponse)
async def control_tab(request: Request, session: SessionDep, node: NodeDep) -> Response:
    base = f"/ui/sessions/{session.id}/nodes/{node.node_id}"
    context: dict[str, Any] = {"session": session, "node": node, "base": base,
                               "api": f"/api/sessions/{session.id}/nodes/{node.node_id}/control",
                               "ws": f"/ws/sessions/{session.id}/nodes/{node.node_id}/control",
                               "status": None, "error": None, "command_note": None,
                               "sequences": commissioning.sequences_for(node),
                               "keepalive_s": drive_control.KEEPALIVE_TIMEOUT_S, "empty": None,
                               "refused": refused_because(request)}
    if node.catalog is None:  # an empty state, not an error: nothing went wrong, the node needs a profile first
        context["empty"] = _("Node {node} has no device profile: assign one on the Plant page to control it.").format(
            node=node.node_id)
        return templates.TemplateResponse(request, "node/control_body.html", context)
    if family_of(node.catalog) is None:
        context["empty"] = _("{device} has no drive control word DriveBench knows (its profile has no control "
                             "section, its object dictionary no CiA 402 0x6040/0x6041): there is nothing to "
                             "control.").format(device=node.device_name)
        return templates.TemplateResponse(request, "node/control_body.html", context)
    try:
        fam = drive_control.family(node)
        context["diagram"] = _diagram(fam)
        context["status"] = await drive_control.read_status(session, node)
    except DriveBenchError as exc:  # without its status word there is no panel to show
        context["error"] = exc
        return templates.TemplateResponse(request, "node/control_body.html", context)
    context["missing"] = drive_control.missing_actuals(node)
    context["missing_why"] = drive_control.missing_why(node)
    unread: dict[str, str] = {}  # a part the drive would not give is marked; the rest of the panel stays
    context["unread_parts"] = unread
    noted = drive_control.or_noted
    context["command_note"] = await noted(unread, _("Command source"), fault_words.command_source_note(session, node),
                                          None)
    context["jog"] = await noted(unread, _("Jog"), drive_control.jog_plan(session, node), None)
    context["sources"] = await noted(unread, _("Actual values"), drive_control.actual_sources(session, node), None)
    if fam.generic:
        context["motion"] = await noted(unread, _("Positioning, velocity and homing"), motion.info(session, node), None)
    context["scope_channels"] = panel_channels(session, node.node_id)
    return templates.TemplateResponse(request, "node/control_body.html", context)
