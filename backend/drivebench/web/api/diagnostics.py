"""Node health, EMCY history, an EtherCAT slave's object list (SDO information), heartbeat set-up, the diagnostics
report and remote-diagnostics share links."""

from __future__ import annotations

import time
from typing import Annotated

from fastapi import APIRouter, Path, Request, status
from fastapi.responses import HTMLResponse, Response
from pydantic import BaseModel, Field

from drivebench.services.monitoring import diagnostics, fault_words, object_list
from drivebench.services.monitoring.diagnostics import EmcyRecord, GuardingPublic, HeartbeatSetup, NodeHealth
from drivebench.services.monitoring.object_list import ObjectListComparison
from drivebench.services.monitoring.remote_content import SessionContent, session_content
from drivebench.services.users.sharing import DEFAULT_SHOWS, SHOWS
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep, StateDep
from drivebench.web.safety import WriteCtxDep
from drivebench.web.share_links import IssuedShareLink, ShareLinkPublic, issued_link, share_link_public
from drivebench.web.templating import templates

# set-up writes take the node lease (WriteCtxDep)
router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["diagnostics"])


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
    shows: list[str] = Field(default_factory=lambda: list(DEFAULT_SHOWS), max_length=len(SHOWS),
                             description=f"What the link shows, of {', '.join(SHOWS)}")


@router.get("/sessions/{session_id}/nodes/{node_id}/object-list", response_model=ObjectListComparison)
async def object_list_of(session: SessionDep, node: NodeDep) -> ObjectListComparison:
    """An EtherCAT slave's object list through the CoE SDO information service, against its profile."""
    return await object_list.compare(session, node.node_id)


@router.get("/health/nodes", response_model=list[SessionHealth])
async def network_health(state: StateDep) -> list[SessionHealth]:
    """Every open session's nodes as the heartbeat and EMCY consumers see them (what the remote view shows)."""
    return [SessionHealth(session_id=s.id, name=s.name, bus=str(s.spec), nodes=diagnostics.network_health(s))
            for s in state.manager.list()]


@router.get("/remote/{token}/content", response_model=list[SessionContent])
async def remote_content(state: StateDep, token: Annotated[str, Path(max_length=80)]) -> list[SessionContent]:
    """What the link shows beyond node health (its ``shows``), from what the server already holds: no bus traffic."""
    link = state.share_links.check(token)
    return [session_content(session, link.shows) for session in state.manager.list()]


@router.get("/sessions/{session_id}/nodes/{node_id}/emcy", response_model=list[EmcyRecord])
async def emcy_history(session: SessionDep, node: NodeDep) -> list[EmcyRecord]:
    """The node's emergency telegrams, newest first, decoded with the manual's texts."""
    return diagnostics.emcy_history(session, node.node_id)


@router.get("/sessions/{session_id}/nodes/{node_id}/faults", response_model=fault_words.Faults)
async def faults_of(session: SessionDep, node: NodeDep) -> fault_words.Faults:
    """The present fault and the fault history in the manual's words (from the EMCY consumer), the profile's
    fault parameters as read now and why commands may do nothing (its command source)."""
    return await fault_words.faults(session, node)


@router.get("/sessions/{session_id}/nodes/{node_id}/heartbeat", response_model=HeartbeatSetup)
async def heartbeat_setup(session: SessionDep, node: NodeDep) -> HeartbeatSetup:
    """Heartbeat producer time (0x1017) and consumer entries (0x1016) read from the device."""
    return await diagnostics.read_heartbeat_setup(session, node.node_id)


@router.put("/sessions/{session_id}/nodes/{node_id}/heartbeat/producer", response_model=HeartbeatSetup)
async def set_producer(session: SessionDep, node: NodeDep, body: ProducerTime, ctx: WriteCtxDep) -> HeartbeatSetup:
    return await diagnostics.write_heartbeat_producer(session, node.node_id, ctx, body.time_ms)


@router.put("/sessions/{session_id}/nodes/{node_id}/heartbeat/consumers/{slot}", response_model=HeartbeatSetup)
async def set_consumer(session: SessionDep, node: NodeDep, slot: int, body: ConsumerEntry,
                       ctx: WriteCtxDep) -> HeartbeatSetup:
    return await diagnostics.write_heartbeat_consumer(session, node.node_id, ctx, slot, body.producer_id,
                                                      body.time_ms)


@router.put("/sessions/{session_id}/nodes/{node_id}/guarding", response_model=GuardingPublic)
async def set_guarding(session: SessionDep, node: NodeDep, body: GuardingRequest, ctx: WriteCtxDep) -> GuardingPublic:
    """Node guarding for devices that use it instead of heartbeat: writes 0x100C/0x100D, then guards the node."""
    return await diagnostics.start_guarding(session, node.node_id, ctx, body.guard_time_ms, body.life_time_factor)


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


@router.post("/share-links", response_model=IssuedShareLink, status_code=status.HTTP_201_CREATED)
async def create_share_link(request: Request, state: StateDep, body: ShareLinkCreate) -> IssuedShareLink:
    """A link for the remote view; its token and URL are in this answer only."""
    return issued_link(state.share_links.create(body.ttl_minutes * 60, body.label, body.shows), request)


@router.get("/share-links", response_model=list[ShareLinkPublic])
async def list_share_links(state: StateDep) -> list[ShareLinkPublic]:
    """The active links, without their tokens."""
    return [share_link_public(link) for link in state.share_links.active()]


@router.delete("/share-links/{link_id}", status_code=status.HTTP_204_NO_CONTENT)
async def revoke_share_link(state: StateDep, link_id: Annotated[str, Path(max_length=80)]) -> Response:
    """Revoke a link by its id (or by its token)."""
    state.share_links.revoke(link_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
