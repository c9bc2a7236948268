"""Sessions (CAN buses), their nodes, NMT and node scan."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, status
from pydantic import BaseModel, Field, model_validator

from drivebench.protocol.nmt import COMMAND_BY_NAME
from drivebench.services.views import NodePublic, SessionPublic, node_public, nodes_public, session_public
from drivebench.transport.bus import BusSpec, known_interfaces
from drivebench.web.deps import ManagerDep, NodeDep, SessionDep

router = APIRouter(prefix="/api", tags=["sessions"])

NmtName = Literal["start", "stop", "pre-operational", "reset-node", "reset-communication"]


class SessionCreate(BaseModel):
    """Either ``bus`` (``socketcan:can0@500000``, ``socketcand:HOST:PORT/can0``) or interface/channel/bitrate."""

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

    def spec(self) -> BusSpec:
        if self.bus:
            return BusSpec.parse(self.bus)
        return BusSpec(interface=self.interface or "", channel=self.channel or "", bitrate=self.bitrate)


class NodeCreate(BaseModel):
    node_id: int = Field(ge=1, le=127)
    profile_id: str | None = None
    name: str | None = Field(None, max_length=80)


class NmtRequest(BaseModel):
    command: NmtName
    node_id: int = Field(0, ge=0, le=127, description="0 = all nodes (broadcast)")


class NodeNmtRequest(BaseModel):
    command: NmtName


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
async def add_node(body: NodeCreate, session: SessionDep) -> NodePublic:
    node = session.add_node(body.node_id, body.profile_id, body.name)
    return node_public(session, node)


@router.get("/sessions/{session_id}/nodes/{node_id}", response_model=NodePublic)
async def get_node(session: SessionDep, node: NodeDep) -> NodePublic:
    return node_public(session, node)


@router.delete("/sessions/{session_id}/nodes/{node_id}", status_code=status.HTTP_204_NO_CONTENT)
async def remove_node(session: SessionDep, node: NodeDep) -> None:
    session.remove_node(node.node_id)


@router.post("/sessions/{session_id}/nmt", response_model=list[NodePublic])
async def nmt_broadcast(body: NmtRequest, session: SessionDep) -> list[NodePublic]:
    """Send an NMT command to one node or (node_id 0) to all nodes."""
    await session.nmt(COMMAND_BY_NAME[body.command], body.node_id)
    return nodes_public(session)


@router.post("/sessions/{session_id}/nodes/{node_id}/nmt", response_model=NodePublic)
async def nmt_node(body: NodeNmtRequest, session: SessionDep, node: NodeDep) -> NodePublic:
    await session.nmt(COMMAND_BY_NAME[body.command], node.node_id)
    return node_public(session, node)


@router.post("/sessions/{session_id}/scan", response_model=list[NodePublic])
async def scan(session: SessionDep, body: ScanRequest | None = None) -> list[NodePublic]:
    """Find the nodes on the bus, read their identity (0x1018) and pick a profile for each."""
    await session.scan((body or ScanRequest()).timeout_s)
    return nodes_public(session)
