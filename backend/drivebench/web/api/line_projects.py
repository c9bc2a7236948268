"""Line projects (issue 32): list, make one from a planned network, export (JSON | lely YAML), import (recreates the
planned network, the parameter sets and the profile references), the boot-up check of a session against a project,
and per node the concise DCF (preview decoded, the file, the download to the node)."""

from __future__ import annotations

import asyncio
import base64
from pathlib import PurePath
from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request, Response
from pydantic import BaseModel, Field

from drivebench.device.formats.concise_dcf import decode, encode
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.profile import Profile
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.line import files
from drivebench.services.line.boot_check import BootCheck, boot_check
from drivebench.services.line.master_dcf import master_entries, master_preview
from drivebench.services.line.project import PDO_INDICES, LineProject, ProjectNode
from drivebench.services.line.store import (
    LineProjectStore,
    LineProjectSummary,
    OpenedProject,
    StoredProject,
    build_project,
    open_project,
)
from drivebench.services.planning.planned_networks import PlannedNetworkStore
from drivebench.services.sets import concise_sets, set_formats
from drivebench.services.sets.parameter_sets import ParameterSetStore
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import MAX_ROW_ID, ManagerDep, RowId, StateDep
from drivebench.web.safety import AuditUserDep, WriteCtxDep, confirmation

router = APIRouter(route_class=DeferredRoute, prefix="/api/line-projects", tags=["line projects"])
NodeId = Annotated[int, Field(ge=1, le=127)]
Format = Literal["json", "yaml"]


class ProjectIn(BaseModel):
    """A project made of a saved planned network: the set chosen per node, the nodes the line may miss."""

    network_id: int = Field(ge=1, le=MAX_ROW_ID)
    name: str | None = Field(None, min_length=1, max_length=200)
    sets: dict[NodeId, Annotated[int, Field(ge=1, le=MAX_ROW_ID)]] = Field(default_factory=dict)
    """Node id -> parameter set id."""
    optional: list[NodeId] = Field(default_factory=list, max_length=127)


class DownloadIn(BaseModel):
    session: str = Field(max_length=200)
    confirm: object = None
    confirm_values: object = None


@router.get("", response_model=list[LineProjectSummary])
def list_projects() -> list[LineProjectSummary]:
    return LineProjectStore().list()


@router.post("", response_model=StoredProject, status_code=201)
def make_project(body: ProjectIn, state: StateDep) -> StoredProject:
    network = PlannedNetworkStore().get(body.network_id)
    sets_store = ParameterSetStore()
    sets = {node_id: sets_store.get(set_id) for node_id, set_id in body.sets.items()}
    plan = network.plan.model_copy(update={"name": body.name or network.plan.name})
    project = build_project(plan, state.registry, sets, optional=set(body.optional))
    return LineProjectStore().save(project, network.id)


def _format_of(filename: str, given: Format | None) -> Format:
    if given is not None:
        return given
    return "yaml" if PurePath(filename).suffix.lower() in (".yaml", ".yml") else "json"


def _namer(state: StateDep) -> files.Namer:
    def name(node: ProjectNode, index: int, subindex: int) -> str:
        if node.profile is not None:
            try:
                found = catalog_for(state.registry.get(node.profile.id)).by_address(index, subindex)
            except DriveBenchError:
                found = None
            if found is not None:
                return found.ref
        return f"0x{index:04X}" if subindex == 0 else f"0x{index:04X}.{subindex}"
    return name


def _addresser(state: StateDep) -> files.Addresser:
    def address(node: ProjectNode, ref: str) -> tuple[int, int] | None:
        if node.profile is None:
            return None
        try:
            item = catalog_for(state.registry.get(node.profile.id)).resolve(ref)
        except DriveBenchError:
            return None
        return item.index, item.subindex
    return address


@router.post("/import", response_model=OpenedProject, status_code=201)
async def import_project(request: Request, state: StateDep, user: AuditUserDep,
                         filename: Annotated[str, Query(max_length=200)] = "project.json",
                         format: Annotated[Format | None, Query(description="json | yaml (default: by the file name)")]
                         = None) -> OpenedProject:
    """Open a project file (the body): on this server it recreates the planned network, the parameter sets and the
    profile references. A file that does not parse: 422 naming the file, the line and the reason; nothing stored."""
    content = await request.body()
    if _format_of(filename, format) == "yaml":
        project = files.from_yaml(content, filename, _namer(state), lambda index: index in PDO_INDICES)
    else:
        project = files.from_json(content, filename)
    return await asyncio.to_thread(open_project, project, state.registry, user=user)


@router.get("/{project_id}", response_model=StoredProject)
def get_project(project_id: RowId) -> StoredProject:
    return LineProjectStore().get(project_id)


@router.delete("/{project_id}", status_code=204)
def delete_project(project_id: RowId) -> Response:
    LineProjectStore().delete(project_id)
    return Response(status_code=204)


def _file_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "-" for c in name).strip("-") or "line-project"


@router.get("/{project_id}/export")
def export_project(project_id: RowId, state: StateDep, format: Format = "json") -> Response:
    """The project as one file: JSON (everything) or lely's YAML master configuration (README: what it leaves to
    its ``drivebench`` blocks)."""
    project = LineProjectStore().get(project_id).project
    name = _file_name(project.name)
    if format == "yaml":
        return Response(files.to_yaml(project, _addresser(state)), media_type="application/yaml",
                        headers={"Content-Disposition": f'attachment; filename="{name}.yaml"'})
    return Response(files.to_json(project), media_type="application/json",
                    headers={"Content-Disposition": f'attachment; filename="{name}.json"'})


@router.post("/{project_id}/boot-check", response_model=BootCheck)
async def check_boot(project_id: RowId, manager: ManagerDep,
                     session: Annotated[str, Query(description="Session (bus) to check")]) -> BootCheck:
    """Per project node: 0x1000 and 0x1018 sub 1-4 read and compared with the project (CiA 302-2)."""
    target = manager.get(session)
    project = (await asyncio.to_thread(LineProjectStore().get, project_id)).project
    return await boot_check(project, target)


def _node_values(project: LineProject, node_id: int, state: StateDep) -> tuple[ProjectNode, Profile]:
    node = project.node(node_id)
    if node.profile is None:
        raise InvalidValue(_("Node {node} has no profile in the project: its values cannot be encoded.").format(
            node=node_id))
    return node, state.registry.get(node.profile.id)


@router.get("/{project_id}/master-dcf", response_model=concise_sets.ConcisePreview)
def master_dcf(project_id: RowId) -> concise_sets.ConcisePreview:
    """The master's 0x1F81 and 0x1F84-0x1F88 per node (CiA 302-2) as a concise DCF, decoded."""
    return master_preview(LineProjectStore().get(project_id).project)


@router.get("/{project_id}/master-dcf.bin")
def master_dcf_file(project_id: RowId) -> Response:
    """The master's concise DCF as a file (for its own 0x1F22)."""
    data = encode(master_entries(LineProjectStore().get(project_id).project))
    return Response(data, media_type="application/octet-stream",
                    headers={"Content-Disposition": 'attachment; filename="master.cdcf"'})


@router.get("/{project_id}/nodes/{node_id}/concise-dcf", response_model=concise_sets.ConcisePreview)
def concise_preview(project_id: RowId, node_id: int, state: StateDep) -> concise_sets.ConcisePreview:
    """The node's parameter set and PDO set-up as a concise DCF, decoded (index, sub-index, name, value)."""
    node, profile = _node_values(LineProjectStore().get(project_id).project, node_id, state)
    return concise_sets.preview(profile, node_id, concise_sets.generate(profile, node.set_values()))


@router.get("/{project_id}/nodes/{node_id}/concise-dcf.bin")
def concise_file(project_id: RowId, node_id: int, state: StateDep) -> Response:
    """The concise DCF as a file (what 0x1F22 sub <node> takes)."""
    node, profile = _node_values(LineProjectStore().get(project_id).project, node_id, state)
    data = concise_sets.generate(profile, node.set_values())
    return Response(data, media_type="application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="node-{node_id}.cdcf"'})


@router.post("/{project_id}/nodes/{node_id}/concise-dcf/download", response_model=concise_sets.ConciseResult)
async def concise_download(request: Request, project_id: RowId, node_id: int, body: DownloadIn, state: StateDep,
                           manager: ManagerDep, ctx: WriteCtxDep) -> concise_sets.ConciseResult:
    """Send the node's concise DCF: one transfer to 0x1F22 where its profile has it, else entry by entry through
    the checked write (moving values: 428 until confirmed with the values)."""
    session = manager.get(body.session)
    node, _profile = _node_values((await asyncio.to_thread(LineProjectStore().get, project_id)).project, node_id,
                                  state)
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    return await concise_sets.download(session, node_id, node.set_values(), ctx=ctx)


@router.post("/concise-dcf/from-dcf", response_model=concise_sets.ConcisePreview)
async def concise_from_dcf(request: Request, state: StateDep,
                           profile: Annotated[str | None, Query(max_length=200, description="Target profile (else "
                                                                "the DCF's [DriveBench] ProfileId)")] = None,
                           filename: Annotated[str, Query(max_length=200)] = "node.dcf") -> concise_sets.ConcisePreview:
    """A node's DCF (the body) as a concise DCF: its ParameterValues checked as a set import checks them, decoded."""
    imported = set_formats.import_dcf(await request.body(), state.registry.get, profile_id=profile, source=filename)
    data = concise_sets.generate(imported.profile, imported.values)
    return concise_sets.preview(imported.profile, imported.node_id or 0, data)


class DecodeIn(BaseModel):
    base64: str = Field(max_length=4_000_000)
    profile: str | None = Field(None, max_length=200)


@router.post("/concise-dcf/decode", response_model=concise_sets.ConcisePreview)
def concise_decode(body: DecodeIn, state: StateDep, node_id: int = 0) -> concise_sets.ConcisePreview:
    """Any concise DCF decoded (names from ``profile`` where given)."""
    try:
        data = base64.b64decode(body.base64, validate=True)
    except ValueError as exc:
        raise InvalidValue(_("Not base64: {why}").format(why=exc)) from exc
    decode(data)
    return concise_sets.preview(state.registry.get(body.profile) if body.profile else None, node_id, data)
