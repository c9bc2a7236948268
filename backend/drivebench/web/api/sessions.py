"""Sessions (CAN buses), their nodes, NMT and node scan, the keep-alive of what a client started, node write leases.

NMT start needs ``confirm`` naming the node (``all`` for the broadcast; else 428) and arms the started nodes: the
client must POST ``/api/sessions/{session}/keepalive`` at least every ``keepalive_s`` (default 2 s, at most 10 s)
or the server stops them (quick stop, NMT pre-operational). ``keepalive: false`` (admins only, with a ``reason``,
logged) starts without that guard, for a supervisor that keeps its own.
"""

from __future__ import annotations

import time

from fastapi import APIRouter, Request, status
from pydantic import BaseModel, Field, model_validator

from drivebench.errors import AccessDenied
from drivebench.i18n import _
from drivebench.services.bus.fieldbus import SessionSpec, parse_spec
from drivebench.services.bus.sessions import Session
from drivebench.services.bus.views import NodePublic, SessionPublic, node_public, nodes_public, session_public
from drivebench.services.control import drive_guard
from drivebench.services.params import node_lease
from drivebench.services.profiles import loading as profiles_loading
from drivebench.services.users.principals import Role
from drivebench.transport.bus import BusSpec, known_interfaces
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import ManagerDep, NodeDep, SessionDep, StateDep
from drivebench.web.identity import PrincipalDep
from drivebench.web.nmt import NmtRequest, NodeNmtRequest, send_nmt
from drivebench.web.safety import PanelDep, WriteCtxDep, WriterDep

router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["sessions"])

class SessionCreate(BaseModel):
    """Either ``bus`` (``socketcan:can0@500000``, ``socketcand:HOST:PORT/can0``, ``ethercat-mbg:HOST:PORT``) or
    interface/channel/bitrate."""

    bus: str | None = Field(None, examples=["socketcan:can0@500000"])
    interface: str | None = Field(None, examples=["pcan"])
    channel: str | None = Field(None, examples=["PCAN_USBBUS1"])
    bitrate: int = Field(500_000, gt=0, le=1_000_000)
    name: str | None = Field(None, max_length=80)

    @model_validator(mode="after")
    def _one_form(self) -> SessionCreate:
        if not self.bus and not self.interface:
            raise ValueError("give either 'bus' or 'interface' (and 'channel', 'bitrate')")
        return self

    def spec(self) -> SessionSpec:
        if self.bus:
            return parse_spec(self.bus)
        return BusSpec(interface=self.interface or "", channel=self.channel or "", bitrate=self.bitrate)


class NodeCreate(BaseModel):
    node_id: int = Field(ge=1, le=127)
    profile_id: str | None = None
    name: str | None = Field(None, max_length=80)


class NotHeldOut(BaseModel):
    node: int
    holder: str


class KeepaliveOut(BaseModel):
    nodes: list[int] = Field(description="The nodes this client holds whose deadline restarted")
    timeout_s: float = Field(description="Send the next keep-alive within this time")
    not_held: list[NotHeldOut] = Field(default_factory=list, description="Armed nodes this keep-alive does NOT keep "
                                                                         "alive: another user or client holds them")


class LeaseOut(BaseModel):
    node_id: int
    holder: str | None = Field(None, description="Who writes the node now (None: nobody)")
    where: str | None = None
    since: str | None = None
    expires_in_s: float | None = None
    yours: bool = False
    text: str | None = None


class ScanRequest(BaseModel):
    timeout_s: float = Field(0.5, ge=0.05, le=5)


@router.get("/interfaces", response_model=list[str])
async def interfaces() -> list[str]:
    """python-can interface names this server can open."""
    return known_interfaces()


@router.get("/sessions", response_model=list[SessionPublic])
async def list_sessions(manager: ManagerDep) -> list[SessionPublic]:
    return [session_public(s) for s in manager.list()]


@router.post("/sessions", response_model=SessionPublic, status_code=status.HTTP_201_CREATED)
async def open_session(body: SessionCreate, manager: ManagerDep) -> SessionPublic:
    session = await manager.open(body.spec(), body.name)
    return session_public(session)


@router.get("/sessions/{session_id}", response_model=SessionPublic)
async def get_session(session: SessionDep) -> SessionPublic:
    return session_public(session)


@router.delete("/sessions/{session_id}", status_code=status.HTTP_204_NO_CONTENT)
async def close_session(session: SessionDep, manager: ManagerDep) -> None:
    await manager.close(session.id)


@router.get("/sessions/{session_id}/nodes", response_model=list[NodePublic])
async def list_nodes(session: SessionDep) -> list[NodePublic]:
    return nodes_public(session)


@router.post("/sessions/{session_id}/nodes", response_model=NodePublic, status_code=status.HTTP_201_CREATED)
async def add_node(body: NodeCreate, session: SessionDep, state: StateDep) -> NodePublic:
    await profiles_loading.profiles_known(state.registry, [body.profile_id])  # a stored upload may still load
    node = session.add_node(body.node_id, body.profile_id, body.name)
    return node_public(session, node)


@router.get("/sessions/{session_id}/nodes/{node_id}", response_model=NodePublic)
async def get_node(session: SessionDep, node: NodeDep) -> NodePublic:
    return node_public(session, node)


@router.delete("/sessions/{session_id}/nodes/{node_id}", status_code=status.HTTP_204_NO_CONTENT)
async def remove_node(session: SessionDep, node: NodeDep) -> None:
    session.remove_node(node.node_id)


@router.post("/sessions/{session_id}/nmt", response_model=list[NodePublic],
             responses={428: {"description": "NMT start without the confirmation naming the node (or 'all')"}})
async def nmt_broadcast(request: Request, body: NmtRequest, session: SessionDep, panel: PanelDep,
                        ctx: WriteCtxDep) -> list[NodePublic]:
    """Send an NMT command to one node or (node_id 0) to all nodes. Start: see the module notes (confirm,
    keep-alive)."""
    await send_nmt(request, session, body, body.node_id, panel, ctx)
    return nodes_public(session)


@router.post("/sessions/{session_id}/nodes/{node_id}/nmt", response_model=NodePublic,
             responses={428: {"description": "NMT start without the confirmation naming the node"}})
async def nmt_node(request: Request, body: NodeNmtRequest, session: SessionDep, node: NodeDep,
                   panel: PanelDep, ctx: WriteCtxDep) -> NodePublic:
    await send_nmt(request, session, body, node.node_id, panel, ctx)
    return node_public(session, node)


@router.post("/sessions/{session_id}/keepalive", response_model=KeepaliveOut)
async def keepalive(session: SessionDep, panel: PanelDep) -> KeepaliveOut:
    """Keep alive every node this client started or armed in the session (send it at least every keepalive_s)."""
    guard = drive_guard.guard_for(session)
    nodes = guard.keepalive_all(panel)
    timeout = min((guard.timeouts.get(n, drive_guard.KEEPALIVE_TIMEOUT_S) for n in nodes),
                  default=drive_guard.KEEPALIVE_TIMEOUT_S)
    return KeepaliveOut(nodes=nodes, timeout_s=timeout, not_held=[
        NotHeldOut(node=node, holder=holder) for node, holder in guard.held_elsewhere(panel).items()])


def lease_out(session: Session, node_id: int, writer: node_lease.Writer | None) -> LeaseOut:
    lease = node_lease.leases(session).current(node_id)
    if lease is None:
        return LeaseOut(node_id=node_id)
    return LeaseOut(node_id=node_id, holder=lease.writer.name, where=lease.writer.where,
                    since=time.strftime("%H:%M:%S", time.localtime(lease.since)),
                    expires_in_s=round(lease.expires_in(), 1),
                    yours=writer is not None and lease.writer.same(writer), text=lease.text(node_id))


@router.get("/sessions/{session_id}/nodes/{node_id}/lease", response_model=LeaseOut)
async def get_lease(session: SessionDep, node: NodeDep, writer: WriterDep) -> LeaseOut:
    """Who holds the node's write lease (writes of anyone else get 409 until it is released or expires)."""
    return lease_out(session, node.node_id, writer)


@router.delete("/sessions/{session_id}/nodes/{node_id}/lease", response_model=LeaseOut)
async def release_lease(session: SessionDep, node: NodeDep, writer: WriterDep, principal: PrincipalDep,
                        force: bool = False) -> LeaseOut:
    """Release your lease; ``force=true`` (admins) breaks someone else's (logged)."""
    table = node_lease.leases(session)
    if not table.release(node.node_id, writer) and force:
        if not principal.may(Role.ADMIN):
            raise AccessDenied(_("Only an admin may break another writer's lease."))
        table.break_lease(node.node_id, f"{principal.name} ({writer.client})")
    return lease_out(session, node.node_id, writer)


@router.post("/sessions/{session_id}/scan", response_model=list[NodePublic])
async def scan(session: SessionDep, body: ScanRequest | None = None) -> list[NodePublic]:
    """Find the nodes on the bus, read their identity (0x1018) and pick a profile for each."""
    await session.scan((body or ScanRequest()).timeout_s)
    return nodes_public(session)
