"""Tools JSON API: DIP-switch calculator, COB-ID table, cable planner, network planner (no bus needed)."""

from __future__ import annotations

import contextlib
from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import BaseModel

from drivebench.device.cable import (
    CROSS_SECTIONS_MM2,
    REPEATER_2176_REDUCTION_M,
    SEGMENT_LENGTH_M,
    SELECTION_EXAMPLE,
    TOTAL_LENGTH_M,
    CablePlan,
    plan_cable,
)
from drivebench.device.cobids import NOTES, CobId, PdoIds, cob_ids
from drivebench.device.dip import FAMILIES, LENZE_8400_MOTEC, DipResult, FamilySpec, decode, encode, family_spec
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.services.planner import NetworkPlan, PlanReport, ScanComparison, check_plan, compare_with_scan
from drivebench.web.deps import ManagerDep

router = APIRouter(prefix="/api/tools", tags=["tools"])


class DipAnswer(BaseModel):
    family: FamilySpec
    result: DipResult
    cob_ids: list[CobId]
    """COB-IDs the node uses (empty when the node id is not known, e.g. the parameter value is not given)."""
    cob_id_notes: list[str]


class CobIdAnswer(BaseModel):
    family: str
    node_id: int
    pdo_ids: PdoIds
    cob_ids: list[CobId]
    notes: list[str]


def parse_switches(on: str) -> dict[str, bool]:
    """``"16,4,2,1"`` -> those switches ON (all others OFF)."""
    return {label.strip(): True for label in on.split(",") if label.strip()}


def dip_answer(result: DipResult, pdo_ids: PdoIds = "canopen") -> DipAnswer:
    spec = family_spec(result.family)
    ids: list[CobId] = []
    if result.node_id is not None:
        with contextlib.suppress(DriveBenchError):  # a parameter value outside the range: no COB-IDs to show
            ids = cob_ids(spec.key, result.node_id, pdo_ids=pdo_ids if spec.key == LENZE_8400_MOTEC else "canopen")
    return DipAnswer(family=spec, result=result, cob_ids=ids, cob_id_notes=NOTES[spec.key])


@router.get("/dip", response_model=list[FamilySpec])
async def dip_families() -> list[FamilySpec]:
    """Device families with their switch blocks, baud-rate tables and rules."""
    return list(FAMILIES.values())


@router.get("/dip/{family}", response_model=DipAnswer)
async def dip(
    family: str,
    on: Annotated[str | None, Query(description="Decode: labels of the ON switches, comma separated "
                                                "(16,4,2,1 or S3,S5,S6,S7); empty = all OFF")] = None,
    node_id: Annotated[int | None, Query(ge=0, le=127, description="Encode: node id to set")] = None,
    baud_kbit: Annotated[int | None, Query(description="Encode: baud rate [kbit/s] to set")] = None,
    code_node_id: Annotated[int | None, Query(ge=0, le=255, description="Decode: value of the node-address "
                                                                         "parameter (C00350 ...)")] = None,
    code_baud_kbit: Annotated[int | None, Query(description="Decode: baud rate of the baud-rate parameter")] = None,
    pdo_ids: PdoIds = "canopen",
) -> DipAnswer:
    """Decode switch positions (``on``) or encode a node id and baud rate (``node_id`` + ``baud_kbit``)."""
    if node_id is not None or baud_kbit is not None:
        if node_id is None or baud_kbit is None or on is not None:
            raise InvalidValue("Encode takes node_id and baud_kbit together; decode takes on (switches).")
        return dip_answer(encode(family, node_id, baud_kbit), pdo_ids)
    result = decode(family, parse_switches(on or ""), code_node_id=code_node_id, code_baud_kbit=code_baud_kbit)
    return dip_answer(result, pdo_ids)


@router.get("/cobids", response_model=CobIdAnswer)
async def cobids(family: str, node_id: Annotated[int, Query(ge=1, le=127)],
                 pdo_ids: PdoIds = "canopen") -> CobIdAnswer:
    """Every COB-ID a node uses, hex and decimal, with the Lenze base-ID variant where it differs."""
    key = family_spec(family).key
    return CobIdAnswer(family=key, node_id=node_id, pdo_ids=pdo_ids, cob_ids=cob_ids(key, node_id, pdo_ids=pdo_ids),
                       notes=NOTES[key])


@router.get("/cable", response_model=CablePlan)
async def cable(baud_kbit: int, nodes: Annotated[int, Query(ge=2)], length_m: Annotated[float, Query(gt=0)],
                cross_section_mm2: float = 0.5,
                repeater_reduction_m: Annotated[int, Query(ge=0)] = REPEATER_2176_REDUCTION_M) -> CablePlan:
    """Cable plan from the 8400 motec manual's tables [5-1]/[5-2] (repeaters, segment and total lengths)."""
    return plan_cable(baud_kbit, cross_section_mm2, nodes, length_m, repeater_reduction_m)


@router.get("/cable/tables")
async def cable_tables() -> dict[str, Any]:
    """The manual's tables as printed: total length per baud rate, segment length, the selection example."""
    return {"total_length_m": TOTAL_LENGTH_M, "cross_sections_mm2": CROSS_SECTIONS_MM2,
            "segment_length_m": SEGMENT_LENGTH_M, "selection_example": SELECTION_EXAMPLE}


@router.post("/planner/check", response_model=PlanReport)
async def planner_check(plan: NetworkPlan) -> PlanReport:
    """Findings for a planned network: duplicate node ids, COB-ID collisions, mixed baud rates, ranges."""
    return check_plan(plan)


class CompareRequest(BaseModel):
    plan: NetworkPlan
    session_id: str
    scan: bool = True
    """Scan the bus first (otherwise compare with the nodes the session already knows)."""


@router.post("/planner/compare", response_model=ScanComparison)
async def planner_compare(request: CompareRequest, manager: ManagerDep) -> ScanComparison:
    """Compare a plan with the nodes found on a session's bus."""
    session = manager.get(request.session_id)
    if request.scan:
        await session.scan()
    found = {node.node_id: (node.identity or None) for node in session.nodes.values()}
    return compare_with_scan(request.plan, found)
