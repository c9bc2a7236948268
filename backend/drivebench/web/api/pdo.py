"""PDO configuration of a node: read, mappable objects, apply with a step report."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse, PlainTextResponse
from pydantic import BaseModel, Field

from drivebench.services.pdos import ethercat_pdo, pdo
from drivebench.services.pdos.ethercat_pdo import EcatApplyReport, EcatAssignment
from drivebench.services.pdos.pdo import ApplyReport, Direction, MappedObject, PdoConfig, PdoWrite
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.safety import WriteCtxDep

router = APIRouter(route_class=DeferredRoute, prefix="/api/sessions/{session_id}/nodes/{node_id}/pdos", tags=["pdo"])


@router.get("", response_model=list[PdoConfig])
async def list_pdos(session: SessionDep, node: NodeDep) -> list[PdoConfig]:
    """Every RPDO and TPDO as the device holds it, mapping entries named from the profile."""
    return await pdo.read_pdos(session, node.node_id)


@router.get("/dcf", response_class=PlainTextResponse)
async def dcf(session: SessionDep, node: NodeDep) -> PlainTextResponse:
    """The node as a DCF (CiA 306) whose PDO communication and mapping objects hold the device's values."""
    text = await pdo.export_dcf(session, node.node_id)
    profile_id = node.profile.id if node.profile else "node"
    return PlainTextResponse(text, headers={
        "Content-Disposition": f'attachment; filename="{profile_id}-node{node.node_id}.dcf"'})


@router.get("/mappable/{direction}", response_model=list[MappedObject])
async def mappable(session: SessionDep, node: NodeDep, direction: Direction) -> list[MappedObject]:
    """The objects the profile allows in a PDO of this direction."""
    return pdo.mappable_objects(session, node.node_id, direction)


class MappingWrite(BaseModel):
    entries: list[tuple[int, int]] = Field(description="(index, subindex) of each mapped object, in order")


@router.get("/assignment", response_model=list[EcatAssignment])
async def assignment(session: SessionDep, node: NodeDep) -> list[EcatAssignment]:
    """EtherCAT: the PDO assignment 0x1C12/0x1C13 and each assigned PDO's mapping, read over CoE."""
    return await ethercat_pdo.read_assignments(session, node.node_id)


@router.put("/mapping/{direction}/{number}", response_model=EcatApplyReport, responses={
    409: {"description": "Refused in this EtherCAT state (not Pre-Operational) or while another writer holds the "
                         "node; the body has the step report"},
    422: {"description": "A mapping the profile or the slave refuses; the body has the step report if it was sent"},
    502: {"description": "The slave refused otherwise or reads back differently; the body has the step report"},
    504: {"description": "The slave did not answer; the body has the step report"}})
async def apply_mapping(session: SessionDep, node: NodeDep, direction: Direction, number: int,
                        body: MappingWrite, ctx: WriteCtxDep) -> EcatApplyReport:
    """EtherCAT: write a PDO mapping (sub 0 := 0, the entries, sub 0 := n), then read it back."""
    return await ethercat_pdo.apply_mapping(session, node.node_id, direction, number, body.entries, ctx=ctx)


@router.get("/{direction}/{number}", response_model=PdoConfig)
async def read_one(session: SessionDep, node: NodeDep, direction: Direction, number: int) -> PdoConfig:
    return await pdo.read_pdo(session, node.node_id, direction, number)


@router.put("/{direction}/{number}", response_model=ApplyReport,
            responses={502: {"description": "The device refused a step; the body is the step report"}})
async def apply(session: SessionDep, node: NodeDep, direction: Direction, number: int,
                body: PdoWrite, ctx: WriteCtxDep) -> ApplyReport | JSONResponse:
    """Apply a mapping and communication parameters in the CiA 301 order, then read back."""
    report = await pdo.apply_pdo(session, node.node_id, direction, number, body, ctx=ctx)
    if report.ok:
        return report
    problem = {"type": "/problems/pdo-apply-failed", "title": "PDO not applied", "status": 502,
               "detail": report.message, **report.model_dump(mode="json")}
    return JSONResponse(problem, status_code=502, media_type="application/problem+json")
