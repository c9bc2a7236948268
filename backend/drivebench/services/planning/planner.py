"""Network planner: check a planned CANopen network before it is built, and compare it with a bus scan.

A plan lists nodes (a device of the loaded profiles: a ``switches`` section named by its key, an alias or a profile id,
or any other CANopen profile by its id, planned from its own data and CiA 301, ``device/calculators/bus_devices.py``;
node id, baud rate, the SDO/PDO channels that are on, the standard or the device's alternative PDO identifiers).
``check_plan`` finds duplicate node ids, COB-ID collisions, mixed baud rates and node ids or baud rates a device cannot
use. Plans travel as JSON (``NetworkPlan.model_dump_json`` / ``from_json``).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, Field, ValidationError

from drivebench.device.calculators.bus_devices import BusDevices, BusRules, NotOnCanBus
from drivebench.device.calculators.cable import CablePlan, plan_cable
from drivebench.device.calculators.cobids import (
    STANDARD_IDS,
    CobId,
    PdoIds,
    channels_of,
    cob_ids,
    default_channels,
    partner,
)
from drivebench.device.calculators.dip import SwitchDevices
from drivebench.device.calculators.switches import SwitchesSection
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _, ngettext

Severity = Literal["error", "warning", "info"]


class PlannedNode(BaseModel):
    name: str = ""
    device: str
    """Key of a profile's ``switches`` section, one of its aliases, or the id of a loaded CANopen profile."""
    node_id: int = Field(ge=1, le=127)
    baud_kbit: int
    channels: list[str] | None = None
    """Channels that are on (``pdo1``, ``pdo2``, ``sdo2`` ...); None = the device's factory setting."""
    pdo_ids: PdoIds = STANDARD_IDS
    """``canopen`` or the key of the device's alternative identifiers (others: the standard ones are used)."""

    @property
    def label(self) -> str:
        if self.name:
            return _("node {node} ({name})").format(node=self.node_id, name=self.name)
        return _("node {node}").format(node=self.node_id)


class CableInput(BaseModel):
    cross_section_mm2: float = 0.5
    length_m: float
    repeater_reduction_m: int = 30


class NetworkPlan(BaseModel):
    name: str = "Planned network"
    nodes: list[PlannedNode] = Field(default_factory=list)
    cable: CableInput | None = None

    def to_json(self) -> str:
        return self.model_dump_json(indent=2)

    @classmethod
    def from_json(cls, text: str | bytes) -> NetworkPlan:
        try:
            return cls.model_validate_json(text)
        except ValidationError as exc:
            raise InvalidValue(
                _("Not a network plan: {count} problem(s); first: {where}: {why}").format(
                    count=exc.error_count(), where=exc.errors()[0]["loc"], why=exc.errors()[0]["msg"])
            ) from exc


class Finding(BaseModel):
    kind: Literal[
        "duplicate_node_id",
        "cob_id_collision",
        "mixed_baud",
        "out_of_range",
        "unsupported_baud",
        "unknown_device",
        "not_canopen",
        "unknown_channel",
        "sdo2_reserved",
        "cable",
    ]
    severity: Severity
    message: str
    node_ids: list[int] = Field(default_factory=list)
    cob_id: int | None = None


class CobIdRow(BaseModel):
    node_id: int
    node_name: str
    service: str
    cob_id: int
    hex: str


class PlanReport(BaseModel):
    ok: bool
    """No finding of severity ``error``."""
    findings: list[Finding]
    cob_table: list[CobIdRow]
    cable: CablePlan | None = None


Spec = SwitchesSection | BusRules
"""A planned device's rules: its ``switches`` section, or those derived from its profile."""


@dataclass(frozen=True)
class _Use:
    """One COB-ID a planned node uses."""

    position: int
    node: PlannedNode
    spec: Spec
    cob: CobId


def _channels(node: PlannedNode, spec: Spec) -> set[str]:
    return set(default_channels(spec) if node.channels is None else node.channels) | {"sdo1"}


def check_plan(plan: NetworkPlan, devices: BusDevices | SwitchDevices) -> PlanReport:
    """Findings and COB-ID table of ``plan``; its devices are looked up in ``devices``."""
    findings: list[Finding] = []
    uses: list[_Use] = []
    for pos, node in enumerate(plan.nodes):
        try:
            spec: Spec = devices.get(node.device).spec
        except NotOnCanBus as exc:
            findings.append(Finding(kind="not_canopen", severity="error", node_ids=[node.node_id],
                                    message=f"{node.label}: {exc.shown_detail()}"))
            continue
        except DriveBenchError as exc:
            findings.append(Finding(kind="unknown_device", severity="error",
                                    message=f"{node.label}: {exc.shown_detail()}",
                                    node_ids=[node.node_id]))
            continue
        lo, hi = spec.node_range
        if not lo <= node.node_id <= hi:
            findings.append(Finding(kind="out_of_range", severity="error", node_ids=[node.node_id],
                                    message=_("{node}: {device} accepts node ids {low} … {high}.").format(
                                        node=node.label, device=spec.name, low=lo, high=hi)))
            continue
        if not spec.baud_rates_kbit:
            findings.append(Finding(kind="unsupported_baud", severity="error", node_ids=[node.node_id],
                                    message=_("{node}: the profile of {device} lists no bit rate (an EDS: no "
                                              "[DeviceInfo] BaudRate_xxx = 1).").format(
                                        node=node.label, device=spec.name)))
        elif node.baud_kbit not in spec.baud_rates_kbit:
            findings.append(Finding(kind="unsupported_baud", severity="error", node_ids=[node.node_id],
                                    message=_("{node}: {device} does not support {baud} kbit/s ({rates}).").format(
                                        node=node.label, device=spec.name, baud=node.baud_kbit,
                                        rates=", ".join(map(str, spec.baud_rates_kbit)))))
        channels = _channels(node, spec)
        unknown = channels - set(channels_of(spec))
        if unknown:
            findings.append(Finding(kind="unknown_channel", severity="error", node_ids=[node.node_id],
                                    message=_("{node}: {device} has no channel(s) {unknown} ({channels}).").format(
                                        node=node.label, device=spec.name, unknown=", ".join(sorted(unknown)),
                                        channels=", ".join(channels_of(spec)))))
        alternative = spec.cob_ids.alternative
        pdo_ids = node.pdo_ids if alternative is not None and node.pdo_ids == alternative.key else STANDARD_IDS
        for cob in cob_ids(spec, node.node_id, pdo_ids=pdo_ids, channels=channels):
            if cob.node_specific:
                uses.append(_Use(pos, node, spec, cob))
        findings.extend(_shared_finding(node, spec, channel) for channel in sorted(channels)
                        if any(s.shares_with for s in spec.cob_ids.services if s.channel == channel))
    findings.extend(_duplicates(plan))
    findings.extend(_collisions(uses))
    findings.extend(_mixed_baud(plan))
    cable = None
    if plan.cable is not None and plan.nodes:
        cable, cable_findings = _cable(plan)
        findings.extend(cable_findings)
    table = [
        CobIdRow(node_id=use.node.node_id, node_name=use.node.name, service=use.cob.service, cob_id=use.cob.cob_id,
                 hex=use.cob.hex)
        for use in sorted(uses, key=lambda u: (u.cob.cob_id, u.position))
    ]
    return PlanReport(
        ok=not any(f.severity == "error" for f in findings), findings=findings, cob_table=table, cable=cable
    )


def _shared_finding(node: PlannedNode, spec: Spec, channel: str) -> Finding:
    """A channel whose identifiers are those of another service at a node id further on (SDO2 = SDO1 of address
    + 64): that node id must stay free, and past 127 the identifiers leave the ones of the node ids."""
    shared = sorted((s for s in spec.cob_ids.services if s.channel == channel and s.shares_with),
                    key=lambda s: s.direction != "to node")
    first = shared[0]
    other = partner(spec, first, node.node_id) or node.node_id
    offset = other - node.node_id
    name, base_name = channel.upper(), (first.shares_with or "").split()[0]
    if other > 127:
        ids = "/".join(f"0x{s.base + node.node_id:03X}" for s in shared)
        return Finding(kind="sdo2_reserved", severity="warning", node_ids=[node.node_id],
                       message=_("{node}: {channel} uses {ids}, beyond the {base} identifiers of node ids 1 … 127 "
                                 "({channel} = address + {offset} needs a node id ≤ {most}).").format(
                           node=node.label, channel=name, ids=ids, base=base_name, offset=offset, most=127 - offset))
    return Finding(kind="sdo2_reserved", severity="info", node_ids=[node.node_id],
                   message=_("{node}: {channel} is reached as node id {other} (address + {offset}); node id {other} "
                             "must stay free.").format(node=node.label, channel=name, other=other, offset=offset))


def _duplicates(plan: NetworkPlan) -> list[Finding]:
    by_id: dict[int, list[PlannedNode]] = defaultdict(list)
    for node in plan.nodes:
        by_id[node.node_id].append(node)
    return [
        Finding(
            kind="duplicate_node_id",
            severity="error",
            node_ids=[nid],
            message=(_("Node id {node} is planned {count} times ({names}).") if any(n.name for n in nodes)
                     else _("Node id {node} is planned {count} times.")).format(
                node=nid, count=len(nodes), names=", ".join(n.name for n in nodes if n.name)),
        )
        for nid, nodes in sorted(by_id.items())
        if len(nodes) > 1
    ]


def _explain(first: _Use, second: _Use) -> str:
    """Why two services of different nodes meet on one COB-ID, where the device's rules say it."""
    for use, other in ((first, second), (second, first)):
        svc = use.spec.cob_ids.service(use.cob.service)
        alternative = use.spec.cob_ids.alternative
        if alternative is not None and svc.alternative_base is not None and use.cob.base == svc.alternative_base:
            return " " + _("({alternative} of {service} {alternative_base}: {service} of node {node} equals "
                           "{other_service} of node {other}; use the CANopen base {base}, {remedy})").format(
                alternative=alternative.label, service=svc.name, alternative_base=f"0x{svc.alternative_base:03X}",
                node=use.node.node_id, other_service=other.cob.service, other=other.node.node_id,
                base=f"0x{svc.base:03X}", remedy=alternative.remedy)
    for use, other in ((first, second), (second, first)):
        svc = use.spec.cob_ids.service(use.cob.service)
        reached = partner(use.spec, svc, use.node.node_id)
        if reached is not None and reached == other.node.node_id:
            return " " + _("({channel} of node {node} is reached as node {reached}: address + {offset})").format(
                channel=svc.channel.upper(), node=use.node.node_id, reached=reached,
                offset=reached - use.node.node_id)
    return ""


def _collisions(uses: list[_Use]) -> list[Finding]:
    by_cob: dict[int, list[_Use]] = defaultdict(list)
    for use in uses:
        by_cob[use.cob.cob_id].append(use)
    findings = []
    for cob, users in sorted(by_cob.items()):
        distinct_ids = {use.node.node_id for use in users}
        if len(users) < 2 or len(distinct_ids) < 2:
            continue  # same node id twice is reported once as a duplicate node id
        described = [_("{service} of {node}").format(service=use.cob.service, node=use.node.label) for use in users]
        findings.append(
            Finding(
                kind="cob_id_collision",
                severity="error",
                cob_id=cob,
                node_ids=sorted(distinct_ids),
                message=_("COB-ID {hex} ({cob}) is used by {users}{why}.").format(
                    hex=f"0x{cob:03X}", cob=cob, users=_(" and ").join(described), why=_explain(users[0], users[1])),
            )
        )
    return findings


def _mixed_baud(plan: NetworkPlan) -> list[Finding]:
    by_baud: dict[int, list[int]] = defaultdict(list)
    for node in plan.nodes:
        by_baud[node.baud_kbit].append(node.node_id)
    if len(by_baud) < 2:
        return []
    parts = "; ".join(
        _("{baud} kbit/s: node(s) {nodes}").format(baud=baud, nodes=", ".join(map(str, ids)))
        for baud, ids in sorted(by_baud.items())
    )
    return [
        Finding(
            kind="mixed_baud",
            severity="error",
            node_ids=sorted({n.node_id for n in plan.nodes}),
            message=_("Mixed baud rates — every node on a bus must use the same baud rate: {parts}.").format(
                parts=parts),
        )
    ]


def _cable(plan: NetworkPlan) -> tuple[CablePlan | None, list[Finding]]:
    assert plan.cable is not None
    baud = max({n.baud_kbit for n in plan.nodes})
    try:
        cable = plan_cable(
            baud,
            plan.cable.cross_section_mm2,
            max(len(plan.nodes), 2),
            plan.cable.length_m,
            plan.cable.repeater_reduction_m,
        )
    except DriveBenchError as exc:
        return None, [Finding(kind="cable", severity="error",
                              message=_("Cable: {why}").format(why=exc.shown_detail()))]
    if not cable.feasible:
        return cable, [
            Finding(
                kind="cable",
                severity="error",
                message=_("Cable: {length} m is too long at {baud} kbit/s (max. {most} m).").format(
                    length=f"{plan.cable.length_m:g}", baud=baud, most=f"{cable.max_length_m:g}"),
            )
        ]
    if cable.repeaters:
        return cable, [
            Finding(
                kind="cable",
                severity="info",
                message=ngettext("Cable: {count} repeater needed for {length} m.",
                                 "Cable: {count} repeaters needed for {length} m.", cable.repeaters).format(
                    count=cable.repeaters, length=f"{plan.cable.length_m:g}"),
            )
        ]
    return cable, []
