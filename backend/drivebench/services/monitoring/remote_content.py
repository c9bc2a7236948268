"""What a remote-diagnostics link shows beyond node health, from what the server already holds: the EMCY
consumer's present fault and history (in the manual's words), the parameter values last read by anyone on site (with
their age), and the monitor's load and counters. Nothing here sends a frame: any number of link holders cost the bus
nothing."""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Any

from pydantic import BaseModel

from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.monitoring import diagnostics, fault_words
from drivebench.services.monitoring.monitor import Monitor
from drivebench.services.params import lookup, session_part

LAST_EMCYS = 10


class HeldValue(BaseModel):
    """A diagnosis parameter as last read on site (never read for the link)."""

    ref: str
    name: str
    display: str
    read_at: float
    age_s: float


class NodeContent(BaseModel):
    node_id: int
    device: str
    present: diagnostics.EmcyRecord | None = None
    """The emergency still active, with the manual's text and remedy (``faults``)."""
    history: list[diagnostics.EmcyRecord] | None = None
    """The emergencies that reported an error, newest first, with their times (``faults``)."""
    last_emcys: list[diagnostics.EmcyRecord] | None = None
    """The last emergency telegrams, resets included (``emcy``)."""
    values: list[HeldValue] | None = None
    """The profile's fault and diagnostics parameters as last read, oldest reads marked by age (``parameters``)."""
    not_read: list[str] | None = None
    """Those parameters nobody on site has read yet (``parameters``)."""
    not_covered: str | None = None
    """What the profile's sources did not give, when a fault shown has a number without text (``faults``)."""


class BusContent(BaseModel):
    """Bus load and the monitor's counters (``bus``)."""

    load: dict[str, Any]
    totals: dict[str, Any]
    services: list[dict[str, Any]]
    bus: dict[str, Any]


class SessionContent(BaseModel):
    session_id: str
    name: str
    nodes: list[NodeContent]
    bus: BusContent | None = None


def diagnosis_refs(node: SessionNode) -> list[str]:
    """The parameters that matter for a diagnosis: the profile's present-fault and fault-history parameters, then
    its diagnostics groups' readable ones, each once."""
    refs: list[str] = []
    section = node.profile.faults if node.profile else None
    if section is not None:
        refs += section.present + section.history
    for group in diagnostics.diagnostic_groups(node):
        refs += [item.ref for item in lookup.readable_items(node, group)]
    return list(dict.fromkeys(refs))


def _held_values(session: Session, node: SessionNode, now: float) -> tuple[list[HeldValue], list[str]]:
    state = session.parts.get(session_part.SessionParameters)
    held = state.values.get(node.node_id, {}) if isinstance(state, session_part.SessionParameters) else {}
    values, missing = [], []
    for ref in diagnosis_refs(node):
        value = held.get(ref)
        if value is None:
            missing.append(ref)
            continue
        values.append(HeldValue(ref=value.ref, name=value.name, display=value.display, read_at=value.read_at,
                                age_s=round(max(now - value.read_at, 0.0), 1)))
    return values, missing


def node_content(session: Session, node: SessionNode, shows: Iterable[str], now: float) -> NodeContent:
    shown = set(shows)
    content = NodeContent(node_id=node.node_id, device=node.device_name)
    if "faults" in shown:
        content.present = fault_words.present_fault(session, node)
        content.history = fault_words.fault_history(session, node.node_id)
        shown_faults = [content.present, *content.history]
        if node.profile and node.profile.faults and any(
                record and record.fault and not record.fault.text for record in shown_faults):
            content.not_covered = node.profile.faults.not_covered
    if "emcy" in shown:
        content.last_emcys = diagnostics.emcy_history(session, node.node_id)[:LAST_EMCYS]
    if "parameters" in shown:
        content.values, content.not_read = _held_values(session, node, now)
    return content


def bus_content(session: Session) -> BusContent | None:
    monitor = session.parts.get(Monitor)
    if not isinstance(monitor, Monitor):  # a session without a frame monitor (EtherCAT)
        return None
    snapshot = monitor.live_snapshot()
    return BusContent(load=snapshot["load"], totals=snapshot["totals"], services=snapshot["services"],
                      bus=snapshot["bus"])


def session_content(session: Session, shows: Iterable[str]) -> SessionContent:
    shown = tuple(shows)
    now = time.time()
    nodes = [node_content(session, node, shown, now) for node in session.nodes.values()]
    return SessionContent(session_id=session.id, name=session.name, nodes=nodes,
                          bus=bus_content(session) if "bus" in shown else None)
