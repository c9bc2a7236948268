"""Node health, EMCY history, heartbeat set-up, the diagnostics report and remote-diagnostics share links."""

from __future__ import annotations

import time
from typing import Annotated

from fastapi import APIRouter, Depends, Request, status
from fastapi.responses import HTMLResponse, Response
from pydantic import BaseModel, Field

from drivebench.services import diagnostics
from drivebench.services.diagnostics import EmcyRecord, GuardingPublic, HeartbeatSetup, NodeHealth
from drivebench.services.sharing import ShareLink
from drivebench.web.deps import NodeDep, SessionDep, StateDep
from drivebench.web.safety import ACTING
from drivebench.web.templating import templates
from drivebench.web.viewer import require_engineer

router = APIRouter(prefix="/api", tags=["diagnostics"], dependencies=[ACTING])  # set-up writes take the node lease
EngineerOnly = Depends(require_engineer)


class SessionHealth(BaseModel):
    session_id: str
    name: str
    bus: str
    nodes: list[NodeHealth]


class ProducerTime(BaseModel):
    time_ms: int = Field(ge=0, le=65535, description="0 switches the heartbeat off")


class ConsumerEntry(BaseModel):
    producer_id: int = Field(ge=0, le=127, description="0 = entry unused")
    time_ms: int = Field(ge=0, le=65535)


class GuardingRequest(BaseModel):
    guard_time_ms: int = Field(ge=0, le=65535, description="0 stops node guarding")
    life_time_factor: int = Field(3, ge=0, le=255)


class ShareLinkCreate(BaseModel):
    ttl_minutes: int = Field(60, ge=1, le=7 * 24 * 60)
    label: str = Field("", max_length=80)


class ShareLinkPublic(BaseModel):
    token: str
    url: str
    label: str
    created: float
    expires: float


def share_link_public(link: ShareLink, base_url: str) -> ShareLinkPublic:
    return ShareLinkPublic(token=link.token, url=f"{base_url.rstrip('/')}/remote/{link.token}", label=link.label,
                           created=link.created, expires=link.expires)


@router.get("/health/nodes", response_model=list[SessionHealth])
async def network_health(state: StateDep) -> list[SessionHealth]:
    """Every open session's nodes as the heartbeat and EMCY consumers see them (what the remote view shows)."""
    return [SessionHealth(session_id=s.id, name=s.name, bus=str(s.spec), nodes=diagnostics.network_health(s))
            for s in state.manager.list()]


@router.get("/sessions/{session_id}/nodes/{node_id}/emcy", response_model=list[EmcyRecord])
async def emcy_history(session: SessionDep, node: NodeDep) -> list[EmcyRecord]:
    """The node's emergency telegrams, newest first, decoded with the manual's texts."""
    return diagnostics.emcy_history(session, node.node_id)


@router.get("/sessions/{session_id}/nodes/{node_id}/heartbeat", response_model=HeartbeatSetup)
async def heartbeat_setup(session: SessionDep, node: NodeDep) -> HeartbeatSetup:
    """Heartbeat producer time (0x1017) and consumer entries (0x1016) read from the device."""
    return await diagnostics.read_heartbeat_setup(session, node.node_id)


@router.put("/sessions/{session_id}/nodes/{node_id}/heartbeat/producer", response_model=HeartbeatSetup)
async def set_producer(session: SessionDep, node: NodeDep, body: ProducerTime) -> HeartbeatSetup:
    return await diagnostics.write_heartbeat_producer(session, node.node_id, body.time_ms)


@router.put("/sessions/{session_id}/nodes/{node_id}/heartbeat/consumers/{slot}", response_model=HeartbeatSetup)
async def set_consumer(session: SessionDep, node: NodeDep, slot: int, body: ConsumerEntry) -> HeartbeatSetup:
    return await diagnostics.write_heartbeat_consumer(session, node.node_id, slot, body.producer_id, body.time_ms)


@router.put("/sessions/{session_id}/nodes/{node_id}/guarding", response_model=GuardingPublic)
async def set_guarding(session: SessionDep, node: NodeDep, body: GuardingRequest) -> GuardingPublic:
    """Node guarding for devices that use it instead of heartbeat: writes 0x100C/0x100D, then guards the node."""
    return await diagnostics.start_guarding(session, node.node_id, body.guard_time_ms, body.life_time_factor)


@router.get("/sessions/{session_id}/diagnostics/report", response_class=HTMLResponse)
async def report(request: Request, session: SessionDep) -> Response:
    """A self-contained HTML report (node list, states, EMCY history) to attach to a service ticket."""
    nodes = diagnostics.network_health(session)
    history = {n.node_id: diagnostics.emcy_history(session, n.node_id) for n in nodes}
    html = templates.get_template("report.html").render(session=session, nodes=nodes, history=history,
                                                        created=time.time())
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return HTMLResponse(html, headers={
        "Content-Disposition": f'attachment; filename="drivebench-diagnostics-{session.id}-{stamp}.html"'})


@router.post("/share-links", response_model=ShareLinkPublic, status_code=status.HTTP_201_CREATED)
async def create_share_link(request: Request, state: StateDep, body: ShareLinkCreate) -> ShareLinkPublic:
    link = state.share_links.create(body.ttl_minutes * 60, body.label)
    return share_link_public(link, str(request.base_url))


@router.get("/share-links", response_model=list[ShareLinkPublic], dependencies=[EngineerOnly])
async def list_share_links(request: Request, state: StateDep) -> list[ShareLinkPublic]:
    return [share_link_public(link, str(request.base_url)) for link in state.share_links.active()]


@router.delete("/share-links/{token}", status_code=status.HTTP_204_NO_CONTENT)
async def revoke_share_link(state: StateDep, token: Annotated[str, "share link token"]) -> Response:
    state.share_links.revoke(token)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
