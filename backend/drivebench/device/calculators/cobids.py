"""The COB-IDs a node uses: COB-ID = basic identifier + node id (NMT and SYNC have no node part).

The device's ``switches.cob_ids`` section says which services exist, their base identifiers, whether they are on in
the factory setting, and another set of base identifiers the device can select (``alternative``, e.g. base IDs
that differ from the CiA 301 predefined connection set in one PDO).
"""

from __future__ import annotations

from typing import Annotated, Protocol

from pydantic import BaseModel, StringConstraints, computed_field

from drivebench.device.calculators.switches import INFRASTRUCTURE, CobIdRules, Direction, Service
from drivebench.errors import InvalidValue, OutOfRange
from drivebench.i18n import _

STANDARD_IDS = "canopen"
"""``pdo_ids`` of CiA 301's predefined connection set; a device's ``alternative`` names the other set."""
PdoIds = Annotated[str, StringConstraints(pattern=r"^[a-z0-9][a-z0-9_.-]*$", max_length=64)]
"""``canopen`` or the key of the device's alternative identifiers."""


class CobIdSpec(Protocol):
    """What the COB-ID rules need of a device: a ``switches`` section, or the rules the planner derives for a
    profile without one (``device/calculators/bus_devices.py``)."""

    @property
    def name(self) -> str: ...

    @property
    def node_range(self) -> tuple[int, int]: ...

    @property
    def cob_ids(self) -> CobIdRules: ...


class CobId(BaseModel):
    service: str
    channel: str
    cob_id: int
    direction: Direction
    base: int
    node_specific: bool
    default_on: bool
    source: str
    note: str | None = None

    @computed_field  # type: ignore[prop-decorator]
    @property
    def hex(self) -> str:
        return f"0x{self.cob_id:03X}"


def partner(spec: CobIdSpec, service: Service, node_id: int) -> int | None:
    """The node id whose ``shares_with`` service has the identifier ``service`` has at ``node_id``."""
    if service.shares_with is None:
        return None
    return node_id + service.base - spec.cob_ids.service(service.shares_with).base


def uses_alternative(spec: CobIdSpec, pdo_ids: PdoIds) -> bool:
    """``pdo_ids`` selects the device's alternative identifiers (any other value: the standard ones)."""
    alternative = spec.cob_ids.alternative
    return alternative is not None and pdo_ids == alternative.key


def cob_ids(spec: CobIdSpec, node_id: int, *, pdo_ids: PdoIds = STANDARD_IDS,
            channels: set[str] | None = None) -> list[CobId]:
    """Every COB-ID ``node_id`` uses; with ``channels``, only those plus NMT/SYNC/EMCY/heartbeat."""
    lo, hi = spec.node_range
    if not lo <= node_id <= hi:
        raise OutOfRange(_("{device}: node id {node} is outside {lo} … {hi}.").format(
            device=spec.name, node=node_id, lo=lo, hi=hi))
    alternative = spec.cob_ids.alternative
    if pdo_ids != STANDARD_IDS and not uses_alternative(spec, pdo_ids):
        other = _(" or '{key}' ({name})").format(key=alternative.key, name=alternative.name) if alternative else ""
        raise InvalidValue(_("{device}: no '{ids}' identifiers are defined for this device; use the CANopen "
                             "identifiers ('{standard}'){other}.").format(
                                 device=spec.name, ids=pdo_ids, standard=STANDARD_IDS, other=other))
    result = []
    for svc in spec.cob_ids.services:
        if channels is not None and svc.channel not in channels | set(INFRASTRUCTURE):
            continue
        base = svc.base
        note = None
        if svc.alternative_base is not None and alternative is not None:
            base = svc.alternative_base if uses_alternative(spec, pdo_ids) else svc.base
            note = (f"{alternative.label} 0x{svc.alternative_base:03X} ({alternative.selected_by}) / CANopen "
                    f"0x{svc.base:03X} ({alternative.standard_by})")
        other_node = partner(spec, svc, node_id)
        if other_node is not None and svc.shares_with is not None:
            note = _("= {service} COB-ID of node id {node}").format(service=svc.shares_with.split()[0],
                                                                     node=other_node)
        result.append(CobId(service=svc.name, channel=svc.channel, cob_id=base + (node_id if svc.node_specific else 0),
                            direction=svc.direction, base=base, node_specific=svc.node_specific,
                            default_on=svc.default_on, source=svc.source, note=note))
    return result


def alternative_hint(spec: CobIdSpec | None, node_id: int, cob_id: int) -> str | None:
    """Which of the device's alternative base identifiers ``cob_id`` is at ``node_id`` (``Lenze base ID of
    RPDO2``), or None."""
    alternative = spec.cob_ids.alternative if spec else None
    if spec is None or alternative is None:
        return None
    return next((_("{label} of {service}").format(label=alternative.label, service=svc.name)
                 for svc in spec.cob_ids.services
                 if svc.alternative_base is not None and svc.alternative_base + node_id == cob_id), None)


def channels_of(spec: CobIdSpec) -> list[str]:
    """Switchable channels in table order (``sdo1``, ``pdo1``, ``pdo2``, ``sdo2`` ...)."""
    seen: list[str] = []
    for svc in spec.cob_ids.services:
        if svc.channel not in INFRASTRUCTURE and svc.channel not in seen:
            seen.append(svc.channel)
    return seen


def default_channels(spec: CobIdSpec) -> set[str]:
    return {s.channel for s in spec.cob_ids.services if s.default_on} - set(INFRASTRUCTURE)
