"""The "Line addressing (LSS)" page of a CAN session (linked from its card on the Plant page): fastscan, the found
devices, per device assign node ID + bit rate + store, each step's result next to its action. The page script
(lss.js) calls the JSON API (``/api/sessions/{session}/lss``); the steps that reach every device ask the
confirmation dialog (428, app.js)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.protocol.canopen.lss import BIT_TIMINGS
from drivebench.services.lss.line import BITRATES
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


@router.get("/sessions/{session_id}/lss", response_class=HTMLResponse)
async def lss_page(request: Request, session: SessionDep) -> Response:
    if session.ethercat is not None:
        raise InvalidValue(_("LSS is a CANopen service: session '{session}' is an EtherCAT segment.").format(
            session=session.name))
    return templates.TemplateResponse(request, "lss.html", {"active": "plant", "session": session,
                                                            "bitrates": BITRATES,
                                                            "timings": sorted(BIT_TIMINGS.items())})
