"""What the UI and the REST API show of sessions and nodes (pydantic models, built on demand)."""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any

from pydantic import BaseModel

from drivebench.device.drive.faults import decode_emcy
from drivebench.services.bus.sessions import Session, SessionNode


class EmcyPublic(BaseModel):
    code: str
    error_register: str
    class_text: str
    vendor_text: str | None
    time: float


class NodePublic(BaseModel):
    node_id: int
    device: str
    profile_id: str | None
    nmt_state: str
    state_from_heartbeat: bool
    heartbeat_age_s: float | None
    heartbeat_period_ms: float | None
    heartbeat_lost: bool
    bootups: int
    last_emcy: EmcyPublic | None
    pending_reset: list[str]
    station: int | None = None
    """EtherCAT: the slave's configured station address (the node number is its place in the master's list)."""
    mailbox: dict[str, int] | None = None
    """EtherCAT: mailbox traffic of this slave (requests, responses, aborts, emergencies, timeouts)."""


class SessionPublic(BaseModel):
    id: str
    name: str
    bus: str
    interface: str
    channel: str
    bitrate: int
    simulated: bool
    state: str
    """Bus state: active, warning, passive, bus-off or adapter lost."""
    state_text: str | None = None
    """The bus state in a sentence when it is not plainly fine."""
    opened_at: float
    node_count: int


def vendor_emcy_text(node: SessionNode, code: int, data: bytes = b"") -> str | None:
    """The profile's words for an EMCY: the device's own fault number in ``data`` (the five manufacturer bytes)
    with the manual's text (its ``faults`` section), else the EMCY code's entry."""
    if node.profile is None:
        return None
    entry = next((e for e in node.profile.emcy_codes if e.code == code), None)
    code_text = (f"{entry.vendor_error}: {entry.text}" if entry.vendor_error else entry.text) if entry else None
    fault = decode_emcy(node.profile.faults, code, data)
    if fault is None:
        return code_text
    return f"{fault.label}: {fault.text or (entry.text if entry else '')}".rstrip(": ")


def node_public(session: Session, node: SessionNode, now: float | None = None) -> NodePublic:
    now = now or time.time()
    status = session.heartbeat(node.node_id)
    state, live = session.nmt_state(node.node_id)
    period = status.expected_period_s()
    emcy = session.last_emcy(node.node_id)
    return NodePublic(
        node_id=node.node_id,
        device=node.device_name,
        profile_id=node.profile.id if node.profile else None,
        nmt_state=state,
        state_from_heartbeat=live,
        heartbeat_age_s=status.age_s(now),
        heartbeat_period_ms=round(period * 1000, 1) if period else None,
        heartbeat_lost=status.is_lost(now),
        bootups=status.bootups,
        last_emcy=EmcyPublic(code=f"0x{emcy.code:04X}", error_register=f"0x{emcy.register:02X}",
                             class_text=emcy.class_text, vendor_text=vendor_emcy_text(node, emcy.code, emcy.data),
                             time=emcy.timestamp) if emcy else None,
        pending_reset=sorted(node.pending_reset),
        **_slave_fields(session, node.node_id),
    )


def _slave_fields(session: Session, node_id: int) -> dict[str, Any]:
    master = session.ethercat
    slave = session.slaves.get(node_id)
    if master is None or slave is None:
        return {}
    return {"station": slave.station, "mailbox": asdict(master.counters(node_id))}


def session_public(session: Session) -> SessionPublic:
    return SessionPublic(
        id=session.id, name=session.name, bus=str(session.spec), interface=session.spec.interface,
        channel=session.spec.channel, bitrate=session.spec.bitrate, simulated=session.simulated,
        state=session.bus_state, state_text=session.bus_text, opened_at=session.opened_at,
        node_count=len(session.nodes),
    )


def nodes_public(session: Session) -> list[NodePublic]:
    now = time.time()
    return [node_public(session, node, now) for node in sorted(session.nodes.values(), key=lambda n: n.node_id)]
