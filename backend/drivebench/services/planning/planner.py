"""Network planner: check a planned CANopen network before it is built, and compare it with a bus scan.

A plan lists nodes (device family or profile id, node id, baud rate, the SDO/PDO channels that are on, CANopen
or Lenze PDO identifiers). ``check_plan`` finds duplicate node ids, COB-ID collisions, mixed baud rates and
node ids or baud rates a device cannot use. Plans travel as JSON (``NetworkPlan.model_dump_json`` /
``from_json``).
"""

from __future__ import annotations

from collections import defaultdict
from typing import Literal

from pydantic import BaseModel, Field, ValidationError

from drivebench.device.cable import CablePlan, plan_cable
from drivebench.device.cobids import PdoIds, channels_of, cob_ids, default_channels
from drivebench.device.dip import LENZE_8400_MOTEC, LENZE_EMF2178IB, family_spec, resolve_family
from drivebench.errors import DriveBenchError, InvalidValue

Severity = Literal["error", "warning", "info"]

EXPECTED_VENDOR_ID = {LENZE_8400_MOTEC: 0x3B, LENZE_EMF2178IB: 0x3B}
"""0x1018sub1 a scan should read (8400 motec manual §13: 0x0000003B = Lenze; EMF2178IB: Lenze too)."""


class PlannedNode(BaseModel):
    name: str = ""
    device: str
    """Device family key (``lenze-8400-motec``, ``lenze-emf2178ib``, ``siemens-mm4``) or a profile id."""
    node_id: int = Field(ge=1, le=127)
    baud_kbit: int
    channels: list[str] | None = None
    """Channels that are on (``pdo1``, ``pdo2``, ``sdo2`` ...); None = the device's factory setting."""
    pdo_ids: PdoIds = "canopen"

    @property
    def label(self) -> str:
        return f"node {self.node_id}" + (f" ({self.name})" if self.name else "")


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
                f"Not a network plan: {exc.error_count()} problem(s); first: "
                f"{exc.errors()[0]['loc']}: {exc.errors()[0]['msg']}"
            ) from exc


class Finding(BaseModel):
    kind: Literal[
        "duplicate_node_id",
        "cob_id_collision",
        "mixed_baud",
        "out_of_range",
        "unsupported_baud",
        "unknown_device",
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


def _channels(node: PlannedNode, family: str) -> set[str]:
    return set(default_channels(family) if node.channels is None else node.channels) | {"sdo1"}


def check_plan(plan: NetworkPlan) -> PlanReport:
    findings: list[Finding] = []
    rows: list[tuple[int, PlannedNode, str, int]] = []  # (position in plan, node, service, cob id)
    for pos, node in enumerate(plan.nodes):
        try:
            family = resolve_family(node.device)
        except DriveBenchError as exc:
            findings.append(
                Finding(
                    kind="unknown_device",
                    severity="error",
                    message=f"{node.label}: {exc.detail}",
                    node_ids=[node.node_id],
                )
            )
            continue
        spec = family_spec(family)
        lo = spec.code_node_range[0]
        hi = max(spec.code_node_range[1], spec.switch_node_range[1] if spec.switch_node_range else 0)
        if not lo <= node.node_id <= hi:
            findings.append(
                Finding(
                    kind="out_of_range",
                    severity="error",
                    node_ids=[node.node_id],
                    message=f"{node.label}: {spec.name} accepts node ids {lo} … {hi}.",
                )
            )
            continue
        if node.baud_kbit not in spec.baud_rates_kbit:
            findings.append(
                Finding(
                    kind="unsupported_baud",
                    severity="error",
                    node_ids=[node.node_id],
                    message=f"{node.label}: {spec.name} does not support {node.baud_kbit} kbit/s "
                    f"({', '.join(map(str, spec.baud_rates_kbit))}).",
                )
            )
        channels = _channels(node, family)
        unknown = channels - set(channels_of(family))
        if unknown:
            findings.append(
                Finding(
                    kind="unknown_channel",
                    severity="error",
                    node_ids=[node.node_id],
                    message=f"{node.label}: {spec.name} has no channel(s) "
                    f"{', '.join(sorted(unknown))} ({', '.join(channels_of(family))}).",
                )
            )
        pdo_ids: PdoIds = node.pdo_ids if family == LENZE_8400_MOTEC else "canopen"
        for cob in cob_ids(family, node.node_id, pdo_ids=pdo_ids, channels=channels):
            if cob.node_specific:
                rows.append((pos, node, cob.service, cob.cob_id))
        if "sdo2" in channels:
            findings.append(_sdo2_finding(node))
    findings.extend(_duplicates(plan))
    findings.extend(_collisions(rows))
    findings.extend(_mixed_baud(plan))
    cable = None
    if plan.cable is not None and plan.nodes:
        cable, cable_findings = _cable(plan)
        findings.extend(cable_findings)
    table = [
        CobIdRow(node_id=node.node_id, node_name=node.name, service=service, cob_id=cob, hex=f"0x{cob:03X}")
        for _, node, service, cob in sorted(rows, key=lambda r: (r[3], r[0]))
    ]
    return PlanReport(
        ok=not any(f.severity == "error" for f in findings), findings=findings, cob_table=table, cable=cable
    )


def _sdo2_finding(node: PlannedNode) -> Finding:
    partner = node.node_id + 64
    if partner > 127:
        return Finding(
            kind="sdo2_reserved",
            severity="warning",
            node_ids=[node.node_id],
            message=f"{node.label}: SDO2 uses 0x{0x640 + node.node_id:03X}/0x{0x5C0 + node.node_id:03X}, "
            "beyond the SDO1 identifiers of node ids 1 … 127 (SDO2 = address + 64 needs a node "
            "id ≤ 63).",
        )
    return Finding(
        kind="sdo2_reserved",
        severity="info",
        node_ids=[node.node_id],
        message=f"{node.label}: SDO2 is reached as node id {partner} (address + 64); node id {partner} "
        "must stay free.",
    )


def _duplicates(plan: NetworkPlan) -> list[Finding]:
    by_id: dict[int, list[PlannedNode]] = defaultdict(list)
    for node in plan.nodes:
        by_id[node.node_id].append(node)
    return [
        Finding(
            kind="duplicate_node_id",
            severity="error",
            node_ids=[nid],
            message=f"Node id {nid} is planned {len(nodes)} times"
            + (f" ({', '.join(n.name for n in nodes if n.name)})" if any(n.name for n in nodes) else "")
            + ".",
        )
        for nid, nodes in sorted(by_id.items())
        if len(nodes) > 1
    ]


def _explain(a: tuple[PlannedNode, str], b: tuple[PlannedNode, str]) -> str:
    (na, sa), (nb, sb) = sorted([a, b], key=lambda x: x[1])
    services = {sa.split()[0], sb.split()[0]}
    if services == {"SDO1", "SDO2"}:
        sdo2 = na if sa.startswith("SDO2") else nb
        return f" (SDO2 of node {sdo2.node_id} is reached as node {sdo2.node_id + 64}: address + 64)"
    if services == {"RPDO2", "TPDO2"}:
        rx = na if sa == "RPDO2" else nb
        if rx.pdo_ids == "lenze":
            return (
                f" (Lenze RPDO2 base 0x281: RPDO2 of node {rx.node_id} equals TPDO2 of node {rx.node_id + 1};"
                " use the CANopen base 0x300, C00353 = 1)"
            )
    return ""


def _collisions(rows: list[tuple[int, PlannedNode, str, int]]) -> list[Finding]:
    by_cob: dict[int, list[tuple[int, PlannedNode, str]]] = defaultdict(list)
    for pos, node, service, cob in rows:
        by_cob[cob].append((pos, node, service))
    findings = []
    for cob, users in sorted(by_cob.items()):
        distinct_ids = {node.node_id for _, node, _ in users}
        if len(users) < 2 or len(distinct_ids) < 2:
            continue  # same node id twice is reported once as a duplicate node id
        described = [f"{service} of {node.label}" for _, node, service in users]
        reason = _explain((users[0][1], users[0][2]), (users[1][1], users[1][2]))
        findings.append(
            Finding(
                kind="cob_id_collision",
                severity="error",
                cob_id=cob,
                node_ids=sorted(distinct_ids),
                message=f"COB-ID 0x{cob:03X} ({cob}) is used by " + " and ".join(described) + reason + ".",
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
        f"{baud} kbit/s: node(s) {', '.join(map(str, ids))}" for baud, ids in sorted(by_baud.items())
    )
    return [
        Finding(
            kind="mixed_baud",
            severity="error",
            node_ids=sorted({n.node_id for n in plan.nodes}),
            message=f"Mixed baud rates — every node on a bus must use the same baud rate: {parts}.",
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
        return None, [Finding(kind="cable", severity="error", message=f"Cable: {exc.detail}")]
    if not cable.feasible:
        return cable, [
            Finding(
                kind="cable",
                severity="error",
                message=f"Cable: {plan.cable.length_m:g} m is too long at {baud} kbit/s "
                f"(max. {cable.max_length_m:g} m).",
            )
        ]
    if cable.repeaters:
        return cable, [
            Finding(
                kind="cable",
                severity="info",
                message=f"Cable: {cable.repeaters} repeater(s) needed for {plan.cable.length_m:g} m.",
            )
        ]
    return cable, []
