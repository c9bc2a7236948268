"""The one place that chooses the source of a recording, and what starting it moves.

Every channel the profile lets a TPDO carry, of a node with a free TPDO that can send (operational or startable),
is sampled by PDO; the rest is polled (SDO on CAN, CoE on EtherCAT). With any channel sampled by PDO the source is
one :class:`JoinedScopeSource` on the SYNC's time base (kind "pdo"); with none, polling alone. Sampling by PDO names
in :func:`moving_steps` the nodes it starts (NMT) and the SYNC it produces, which the recording's start has
confirmed like the drive control panel (polling moves nothing).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from drivebench.errors import DriveBenchError
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session
from drivebench.services.params.write_context import Values, WriteContext
from drivebench.services.pdos import pdo
from drivebench.services.scope.joined import JoinedScopeSource, part
from drivebench.services.scope.pdo_plan import plan_recording, polling_texts, without_frames
from drivebench.services.scope.pdo_source import PdoScopeSource
from drivebench.services.scope.poll import PollScopeSource
from drivebench.services.scope.source import ScopeChannel, ScopeSource

MovingStep = tuple[int | None, str, Values]
"""(node id, None: several nodes ("all"); what it does, in words; the values it sends) of one moving-class step."""


def _mappable(session: Session, channel: ScopeChannel) -> bool:
    catalog = pdo.node_catalog(session, channel.node)
    try:
        item = catalog.resolve(channel.ref)
    except DriveBenchError:  # an unknown ref is refused in words by describe() before
        return False
    return any((m.index, m.subindex) == (item.index, item.subindex)
               for m in pdo.mappable_objects(session, channel.node, "tpdo"))


def _not_mappable_texts(session: Session, channels: list[ScopeChannel]) -> list[str]:
    """Why each channel no TPDO may carry is polled, in words (one line per node)."""
    refs: dict[int, list[str]] = {}
    for channel in channels:
        found = refs.setdefault(channel.node, [])
        if channel.ref not in found:
            found.append(channel.ref)
    return [_("Node {node}: {refs} polled: its profile does not list them as TPDO-mappable.").format(
        node=node, refs=", ".join(found)) for node, found in refs.items()]


async def open_source(session: Session, channels: list[ScopeChannel], period_s: float, ctx: WriteContext,
                      *, db_url: str | None = None) -> ScopeSource:
    """The source for ``channels``: PDO where the plan allows it, polling for the rest; InvalidValue in words for
    a recording by PDO that would overload the bus or needs more TPDOs than a node has free."""
    frames = session.network.capabilities.frames
    mappable = [position for position, channel in enumerate(channels) if frames and _mappable(session, channel)]
    why = _not_mappable_texts(session, [c for p, c in enumerate(channels) if frames and p not in mappable])
    if mappable:
        plan = await plan_recording(session, [channels[p] for p in mappable], period_s)
        if plan.tpdos:
            by_pdo = [p for p, slot in zip(mappable, plan.slots, strict=True) if slot is not None]
            slots = [slot for slot in plan.slots if slot is not None]
            plan = dataclasses.replace(plan, channels=tuple(channels[p] for p in by_pdo), slots=tuple(slots))
            polled = [p for p in range(len(channels)) if p not in by_pdo]
            poll = PollScopeSource(session, [channels[p] for p in polled], period_s) if polled else None
            return JoinedScopeSource(PdoScopeSource(session, plan, ctx, db_url=db_url), by_pdo, poll, polled,
                                     why)
        why = plan.texts() + why
    elif not frames:
        why = polling_texts(without_frames(channels))
    return PollScopeSource(session, channels, period_s, why)


def moving_steps(source: ScopeSource) -> list[MovingStep]:
    """What starting ``source`` moves (a source that starts nodes or a SYNC producer says so in ``moving``)."""
    steps: list[MovingStep] = list(getattr(source, "moving", []))
    return steps


def parts(source: ScopeSource) -> list[dict[str, Any]]:
    """How each part of ``source`` samples which nodes, at the rate it really reaches."""
    joined = getattr(source, "parts", None)
    if callable(joined):
        found: list[dict[str, Any]] = joined()
        return found
    return [part(source.kind, list(getattr(source, "nodes", [])), source.period_s)]


SOURCE_NAMES = {"pdo": N_("sampling by PDO"), "sdo-poll": N_("SDO polling"), "coe-poll": N_("CoE polling")}
"""How the page names a source (translated where shown)."""
