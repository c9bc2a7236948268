"""Tools JSON API: DIP-switch calculator, COB-ID table, cable planner, network planner and saved planned networks.

The calculators are pure (no bus, no database): GET with query parameters or POST with a JSON body. Planned
networks live in the database (``/api/planned-networks``); only ``compare`` touches a bus (it scans a session).
"""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Request, Response
from pydantic import BaseModel, Field

from drivebench.device.calculators.bus_devices import BusDevices
from drivebench.device.calculators.cable import (
    CROSS_SECTIONS_MM2,
    REPEATER_2176_REDUCTION_M,
    SEGMENT_LENGTH_M,
    TOTAL_LENGTH_M,
    CablePlan,
    plan_cable,
    selection_example,
)
from drivebench.device.calculators.cobids import STANDARD_IDS, CobId, PdoIds, cob_ids
from drivebench.device.calculators.dip import SwitchDevice, decode, encode
from drivebench.device.calculators.switches import SwitchesSection
from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.planning.planned_networks import (
    LiveComparison,
    PlannedNetwork,
    PlannedNetworkStore,
    PlannedNetworkSummary,
    compare_with_session,
)
from drivebench.services.planning.planner import NetworkPlan, PlanReport, check_plan
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import ManagerDep, RowId, StateDep
from drivebench.web.dip_answer import DipAnswer, dip_answer

router = APIRouter(route_class=DeferredRoute, prefix="/api/tools", tags=["tools"])
planned_router = APIRouter(route_class=DeferredRoute, prefix="/api/planned-networks", tags=["planned networks"])


# --- DIP-switch calculator and COB-IDs -------------------------------------------------------------------------
async def get_devices(state: StateDep) -> BusDevices:
    """The devices of the loaded profiles (built-in and uploaded): the calculator's are those with a ``switches``
    section (``.switches``), the planner's and the COB-ID table's every CANopen profile."""
    return BusDevices(state.registry.all())


DevicesDep = Annotated[BusDevices, Depends(get_devices)]


class DipRequest(BaseModel):
    """Either ``switches`` (decode) or ``node_id`` + ``baud_kbit`` (encode)."""

    switches: dict[str, bool] | None = None
    """Switch label -> ON; switches not named are OFF."""
    code_node_id: int | None = Field(None, ge=0, le=255)
    """Decode: value of the node-address parameter (the section's ``node_parameter``)."""
    code_baud_kbit: int | None = None
    """Decode: baud rate [kbit/s] the baud-rate parameter selects (the section's ``baud_parameter``)."""
    node_id: int | None = Field(None, ge=0, le=127)
    baud_kbit: int | None = None
    pdo_ids: PdoIds = STANDARD_IDS


class CobIdAnswer(BaseModel):
    family: str
    node_id: int
    pdo_ids: PdoIds
    cob_ids: list[CobId]
    notes: list[str]


def parse_switches(on: str) -> dict[str, bool]:
    """``"16,4,2,1"`` -> those switches ON (all others OFF)."""
    return {label.strip(): True for label in on.split(",") if label.strip()}


def calculate(device: SwitchDevice, request: DipRequest) -> DipAnswer:
    if request.node_id is not None or request.baud_kbit is not None:
        if request.node_id is None or request.baud_kbit is None or request.switches is not None:
            raise InvalidValue(_("Encode takes node_id and baud_kbit together; decode takes the switches."))
        return dip_answer(device, encode(device, request.node_id, request.baud_kbit), request.pdo_ids)
    result = decode(device, request.switches or {}, code_node_id=request.code_node_id,
                    code_baud_kbit=request.code_baud_kbit)
    return dip_answer(device, result, request.pdo_ids)


@router.get("/dip", response_model=list[SwitchesSection])
async def dip_families(devices: DevicesDep) -> list[SwitchesSection]:
    """Devices with their switch blocks, baud-rate tables, rules and the manuals' ambiguities: the ``switches``
    sections of the loaded profiles, one per key."""
    return [device.spec for device in devices.switches.all()]


@router.get("/dip/{family}", response_model=DipAnswer)
async def dip(
    family: str,
    on: Annotated[str | None, Query(description="Decode: labels of the ON switches, comma separated "
                                                "(16,4,2,1 or S3,S5,S6,S7); empty = all OFF")] = None,
    node_id: Annotated[int | None, Query(ge=0, le=127, description="Encode: node id to set")] = None,
    baud_kbit: Annotated[int | None, Query(description="Encode: baud rate [kbit/s] to set")] = None,
    code_node_id: Annotated[int | None, Query(ge=0, le=255, description="Decode: value of the node-address "
                                                                         "parameter")] = None,
    code_baud_kbit: Annotated[int | None, Query(description="Decode: baud rate of the baud-rate parameter")] = None,
    pdo_ids: PdoIds = STANDARD_IDS,
    *,
    devices: DevicesDep,
) -> DipAnswer:
    """Decode switch positions (``on``) or encode a node id and baud rate (``node_id`` + ``baud_kbit``)."""
    request = DipRequest(switches=parse_switches(on) if on is not None else None, node_id=node_id,
                         baud_kbit=baud_kbit, code_node_id=code_node_id, code_baud_kbit=code_baud_kbit,
                         pdo_ids=pdo_ids)
    return calculate(devices.switch_device(family), request)


@router.post("/dip/{family}", response_model=DipAnswer)
async def dip_post(family: str, request: DipRequest, devices: DevicesDep) -> DipAnswer:
    """As GET, with the switch positions as a JSON object (``{"switches": {"16": true, "a": true}}``)."""
    return calculate(devices.switch_device(family), request)


@router.get("/cobids", response_model=CobIdAnswer)
async def cobids(family: str, node_id: Annotated[int, Query(ge=1, le=127)], devices: DevicesDep,
                 pdo_ids: PdoIds = STANDARD_IDS) -> CobIdAnswer:
    """Every COB-ID a node uses, hex and decimal, with the device's alternative base ID where it differs (any CANopen
    profile: without a ``switches`` section, from its objects' defaults and CiA 301)."""
    spec = devices.get(family).spec
    return CobIdAnswer(family=spec.key, node_id=node_id, pdo_ids=pdo_ids,
                       cob_ids=cob_ids(spec, node_id, pdo_ids=pdo_ids), notes=spec.cob_ids.notes)


# --- cable and network planner ---------------------------------------------------------------------------------
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
            "segment_length_m": SEGMENT_LENGTH_M, "selection_example": selection_example()}


@router.post("/planner/check", response_model=PlanReport)
async def planner_check(plan: NetworkPlan, devices: DevicesDep) -> PlanReport:
    """Findings for a planned network: duplicate node ids, COB-ID collisions, mixed baud rates, ranges."""
    return check_plan(plan, devices)


@router.post("/planner/compare", response_model=LiveComparison)
async def planner_compare(plan: NetworkPlan, manager: ManagerDep, devices: DevicesDep,
                          session: Annotated[str, Query(description="Session (bus) to scan")],
                          timeout_s: Annotated[float, Query(gt=0, le=5)] = 0.5) -> LiveComparison:
    """Compare an unsaved plan with a live scan of a session's bus."""
    return await compare_with_session(plan, manager.get(session), devices, timeout_s)


# --- saved planned networks ------------------------------------------------------------------------------------
async def get_store() -> PlannedNetworkStore:
    return PlannedNetworkStore()


StoreDep = Annotated[PlannedNetworkStore, Depends(get_store)]


class PlannedNetworkChecked(PlannedNetwork):
    report: PlanReport


@planned_router.get("", response_model=list[PlannedNetworkSummary])
def list_planned(store: StoreDep) -> list[PlannedNetworkSummary]:
    return store.list()


@planned_router.post("", response_model=PlannedNetworkChecked, status_code=201)
def save_planned(plan: NetworkPlan, store: StoreDep, devices: DevicesDep) -> PlannedNetworkChecked:
    """Save a plan (also when it has findings: they come back in ``report``)."""
    saved = store.save(plan)
    return PlannedNetworkChecked(**saved.model_dump(), report=check_plan(saved.plan, devices))


@planned_router.post("/import", response_model=PlannedNetworkChecked, status_code=201)
async def import_planned(request: Request, store: StoreDep, devices: DevicesDep) -> PlannedNetworkChecked:
    """Store a plan exported before (the JSON of ``/export`` as the request body). Bad JSON: 422 with the first
    problem, nothing saved."""
    saved = await asyncio.to_thread(store.import_json, await request.body())
    return PlannedNetworkChecked(**saved.model_dump(), report=check_plan(saved.plan, devices))


@planned_router.get("/{network_id}", response_model=PlannedNetworkChecked)
def get_planned(network_id: RowId, store: StoreDep, devices: DevicesDep) -> PlannedNetworkChecked:
    saved = store.get(network_id)
    return PlannedNetworkChecked(**saved.model_dump(), report=check_plan(saved.plan, devices))


@planned_router.put("/{network_id}", response_model=PlannedNetworkChecked)
def update_planned(network_id: RowId, plan: NetworkPlan, store: StoreDep, devices: DevicesDep) -> PlannedNetworkChecked:
    saved = store.update(network_id, plan)
    return PlannedNetworkChecked(**saved.model_dump(), report=check_plan(saved.plan, devices))


@planned_router.delete("/{network_id}", status_code=204)
def delete_planned(network_id: RowId, store: StoreDep) -> Response:
    store.delete(network_id)
    return Response(status_code=204)


@planned_router.get("/{network_id}/export")
def export_planned(network_id: RowId, store: StoreDep) -> Response:
    """The plan as a JSON file (import it again with ``POST /api/planned-networks/import``)."""
    saved = store.get(network_id)
    filename = "".join(c if c.isalnum() or c in "-_" else "-" for c in saved.name).strip("-") or "network"
    return Response(saved.plan.to_json(), media_type="application/json",
                    headers={"Content-Disposition": f'attachment; filename="{filename}.json"'})


@planned_router.post("/{network_id}/compare", response_model=LiveComparison)
async def compare_planned(network_id: RowId, store: StoreDep, manager: ManagerDep, devices: DevicesDep,
                          session: Annotated[str, Query(description="Session (bus) to scan")],
                          timeout_s: Annotated[float, Query(gt=0, le=5)] = 0.5) -> LiveComparison:
    """Scan the session's bus: which planned nodes answer as the planned device, which are missing or extra."""
    target = manager.get(session)
    saved = await asyncio.to_thread(store.get, network_id)
    return await compare_with_session(saved.plan, target, devices, timeout_s)
