"""Parameters of a node: list/search, read, write (validated, verified), read-all jobs, device commands.

Values travel raw and scaled (``{"raw": 1020, "value": 10.2, "unit": "A", "text": null}``); SDO aborts and
timeouts are problem+json with ``abort_code``/``abort_text``/``node``/``object`` (see ``web/problems.py``).
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field, TypeAdapter, model_validator

from drivebench.config import settings
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.scaling import ScaledValue
from drivebench.errors import DriveBenchError
from drivebench.i18n import shown
from drivebench.services.params import device_commands, factory_compare, lookup, reads, session_part, writes
from drivebench.services.params import parameter_batch as batch
from drivebench.services.params import read_all as read_jobs
from drivebench.services.params.device_commands import DeviceCommand
from drivebench.services.params.parameter_batch import MAX_BATCH_WRITE, Wanted
from drivebench.services.params.session_part import SdoSettings
from drivebench.services.params.values import ParameterValue, WriteResult
from drivebench.services.users import undo as undoing
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import JobsDep, NodeDep, RootDep, SessionDep
from drivebench.web.job_views import JobOut, ParameterValueOut, ValueOut, job_out, value_out
from drivebench.web.lean_route import lean_route, path_int
from drivebench.web.problems import problem_body
from drivebench.web.safety import WriteCtxDep, confirmation
from drivebench.web.state import app_state

# Every route that writes (or starts a job that does) takes the request's WriteContext (WriteCtxDep) and hands it to
# the service; a read takes none (benchmarks/RESULTS.md, Request path).
router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["parameters"])
NODE = "/sessions/{session_id}/nodes/{node_id}"


# --- models --------------------------------------------------------------------------------------------
class BatchRead(BaseModel):
    refs: list[str] = Field(min_length=1, max_length=reads.MAX_BATCH,
                            description="Parameter refs as the single read takes them (C00011, 0x1017.0, P0700)")


class BatchReadItem(BaseModel):
    """One ref of a batch read: its value, or the problem it met (``error``, the words of a single read's answer)."""

    ref: str
    ok: bool
    value: ParameterValueOut | None = None
    error: dict[str, Any] | None = None


class BatchReadOut(BaseModel):
    node_id: int
    items: list[BatchReadItem]


class ParameterInfo(BaseModel):
    ref: str
    name: str
    group: str
    index: str
    subindex: int
    address: str
    data_type: str
    access: str
    writable: bool
    unit: str | None
    min: float | int | None
    max: float | int | None
    default: float | int | str | None
    """The profile's default as it gives it (engineering units; None for a ``$NODEID`` formula)."""
    factory: str | None = None
    """The factory value for this node as a value is shown (``10.20 A``, ``0x00000185``: the profile's default, its
    ``$NODEID`` formula or CiA 301's pre-defined connection set); None where no source gives one."""
    selection: dict[int, str]
    bits: dict[int, str]
    reset_required: bool
    last: ParameterValueOut | None = None
    """The value read last (by this server), if any."""
    read_failed: str | None = None
    """Why the last read job could not read it (an abort, a timeout, the node silent); None after a good read."""


class ParameterList(BaseModel):
    node_id: int
    device: str
    groups: list[str]
    """Groups in the manual's order."""
    parameters: list[ParameterInfo]
    pending_reset: list[str]


class GivenValue(BaseModel):
    """Either ``value`` (engineering units or what a user typed: ``10.2``, ``"10.20 A"``, ``"250 kbit/s"``) or
    ``raw`` (the device's integer)."""

    value: int | float | str | None = None
    raw: int | None = None

    @model_validator(mode="after")
    def _one_of(self) -> GivenValue:
        if (self.value is None) == (self.raw is None):
            raise ValueError("give exactly one of 'value' and 'raw'")
        return self


CHECK = Field(True, description="Validate against the profile before sending (false: the device decides; the value "
                                "must still fit the data type)")
VERIFY = Field(True, description="Read the value back after writing and compare")
CONFIRM = Field(None, description="The node id, for a write that can make the drive move (a control word that "
                                  "enables, a setpoint, the mode, a command source: the profile marks them); or "
                                  "X-DriveBench-Confirm")
CONFIRM_VALUES = Field(None, description="With confirm: the values the 428 named (confirm_values), repeated; or "
                                         "X-DriveBench-Confirm-Values")


class ParameterWrite(GivenValue):
    check: bool = CHECK
    verify: bool = VERIFY
    confirm: int | str | None = CONFIRM
    confirm_values: dict[str, Any] | None = CONFIRM_VALUES


class BatchWriteEntry(GivenValue):
    ref: str


class BatchWrite(BaseModel):
    """Values to write in their order (see ``services/params/parameter_batch.py``); ``confirm`` covers every write of
    the batch that can make the drive move."""

    items: list[BatchWriteEntry] = Field(min_length=1, max_length=MAX_BATCH_WRITE)
    check: bool = CHECK
    verify: bool = VERIFY
    confirm: int | str | None = CONFIRM
    confirm_values: dict[str, Any] | None = CONFIRM_VALUES


class UndoRequest(BaseModel):
    confirm: int | str | None = CONFIRM
    confirm_values: dict[str, Any] | None = CONFIRM_VALUES


class WriteOut(BaseModel):
    ref: str
    written: ValueOut
    read_back: ParameterValueOut | None
    verified: bool | None
    mismatch: str | None
    reset_required: bool
    pending_reset: list[str]


class UndoOut(WriteOut):
    undone: int
    """The audit record whose old value was written back (the new record's origin is ``undo <undone>``)."""
    session_id: str
    node_id: int


class BatchWriteItem(BaseModel):
    """One value of a batch write: ``written`` (``result`` as a single write answers), ``failed`` (``error``, the
    problem in words; the batch stopped here) or ``not sent`` (after a failed one)."""

    ref: str
    ok: bool
    state: str
    result: WriteOut | None = None
    error: dict[str, Any] | None = None


class BatchWriteOut(BaseModel):
    node_id: int
    complete: bool
    """Every value was written."""
    written: int
    items: list[BatchWriteItem]
    pending_reset: list[str]


class GroupRead(BaseModel):
    group: str


class SessionRead(BaseModel):
    node_ids: list[Annotated[int, Field(ge=1, le=127)]] | None = Field(
        None, description="Nodes to read; all nodes of the session with a profile when omitted")


class CommandOut(BaseModel):
    command: str
    via: str
    detail: str
    pending_reset: list[str]


class SdoSettingsModel(BaseModel):
    timeout_s: float = Field(0.5, ge=0.01, le=30)
    retries: int = Field(1, ge=0, le=10)
    use_sdo2: bool = True


class ComparedOut(BaseModel):
    """One setting in the comparison with the factory setting."""

    ref: str
    name: str
    group: str
    address: str
    value: ParameterValueOut | None
    factory_raw: int | float | str | None
    factory: str | None
    """The factory value as the Parameters tab shows a value (``5.0 s``); None: no source gives one."""
    problem: str | None = None


class ComparisonOut(BaseModel):
    node_id: int
    device: str
    changed: list[ComparedOut]
    """Settings whose value differs from the factory value."""
    no_factory_value: list[ComparedOut]
    """Settings with no known factory value (the profile gives none): listed apart, never compared."""
    not_read: list[ComparedOut]
    same: int
    """How many settings hold their factory value."""


# --- conversions -----------------------------------------------------------------------------------------
def _scaled_out(scaled: ScaledValue) -> ValueOut:
    raw = scaled.raw.hex() if isinstance(scaled.raw, bytes) else scaled.raw
    value = scaled.value.hex() if isinstance(scaled.value, bytes) else scaled.value
    return ValueOut(raw=raw, value=value, unit=scaled.unit, text=scaled.text)


def info_out(item: Item, last: ParameterValue | None, read_failed: str | None = None,
             node_id: int | None = None) -> ParameterInfo:
    entry = item.entry
    return ParameterInfo(
        factory=factory_compare.factory_shown(item, node_id) if node_id is not None else None,
        ref=item.ref, name=item.name, group=item.group, index=f"0x{item.index:04X}", subindex=item.subindex,
        address=item.address, data_type=entry.data_type.value, access=entry.access.value,
        writable=entry.access.writable, unit=entry.unit, min=entry.min, max=entry.max, default=entry.default,
        selection=entry.selection, bits=entry.bits, reset_required=entry.reset_required,
        last=value_out(last) if last else None, read_failed=shown(read_failed) if read_failed else None)


def compared_out(compared: factory_compare.Compared) -> ComparedOut:
    item, factory = compared.item, compared.factory
    return ComparedOut(ref=item.ref, name=item.name, group=item.group, address=item.address,
                       value=value_out(compared.value) if compared.value else None,
                       factory_raw=factory.raw.hex() if factory and isinstance(factory.raw, bytes)
                       else factory.raw if factory else None,
                       factory=factory.display if factory else None, problem=compared.problem)


def comparison_out(found: factory_compare.Comparison) -> ComparisonOut:
    return ComparisonOut(node_id=found.node_id, device=found.device, same=found.same,
                         changed=[compared_out(c) for c in found.changed],
                         no_factory_value=[compared_out(c) for c in found.no_factory_value],
                         not_read=[compared_out(c) for c in found.not_read])


def write_out(result: WriteResult, pending: set[str]) -> WriteOut:
    return WriteOut(ref=result.ref, written=_scaled_out(result.written),
                    read_back=value_out(result.read_back) if result.read_back else None,
                    verified=result.verified, mismatch=result.mismatch and shown(result.mismatch),
                    reset_required=result.reset_required,
                    pending_reset=sorted(pending))


# --- routes ----------------------------------------------------------------------------------------------
@router.get(NODE + "/parameters", response_model=ParameterList)
async def list_parameters(session: SessionDep, node: NodeDep,
                          q: Annotated[str, Query(description="Code (C00088, 88), name words or index (0x5FA7)")] = "",
                          group: str | None = None,
                          parameter_set: Annotated[int, Query(ge=1, le=4, description=(
                              "Parameter set whose codes to list where the device keeps codes per set "
                              "(set 2 lists C2012 for C0012)"))] = 1) -> ParameterList:
    last = session_part.service(session).values.get(node.node_id, {})
    failures = session_part.service(session).failures.get(node.node_id, {})
    found = lookup.items(node, q, group, parameter_set)
    return ParameterList(node_id=node.node_id, device=node.device_name, groups=lookup.groups(node),
                         parameters=[info_out(item, last.get(item.ref), failures.get(item.ref), node.node_id)
                                     for item in found],
                         pending_reset=sorted(node.pending_reset))


async def read_parameter(session: SessionDep, node: NodeDep, ref: str,
                         transfer: Annotated[str, Query(pattern="^(auto|block)$")] = "auto") -> ParameterValueOut:
    """Read from the device now (``transfer=block`` for a CiA 301 block upload)."""
    return value_out(await reads.read(session, node.node_id, ref, transfer=transfer))


_VALUE_JSON = TypeAdapter(ParameterValueOut)


async def _lean_read(request: Request) -> Response | None:
    """``read_parameter`` without FastAPI's dependency solving, for the read clients poll: a plain node id and no
    query (anything else, ``transfer=block`` too, takes the full path). The same look-ups in the same order
    (session, node), the same service call, the same body."""
    params = request.scope["path_params"]
    node_id = path_int(params["node_id"], 1, 127)
    if node_id is None or request.scope["query_string"]:
        return None
    state = app_state(request.app)
    session = state.manager.get(params["session_id"])
    node = session.node(node_id)
    value = value_out(await reads.read(session, node.node_id, params["ref"]))
    return Response(_VALUE_JSON.dump_json(value, by_alias=True), media_type="application/json")


router.add_api_route(NODE + "/parameters/{ref:path}", read_parameter, methods=["GET"],
                     response_model=ParameterValueOut, route_class_override=lean_route(_lean_read))


@router.post(NODE + "/parameters:read", response_model=BatchReadOut)
async def read_parameters(request: Request, session: SessionDep, node: NodeDep, body: BatchRead) -> BatchReadOut:
    """Read many parameters in one request, in the order given; each answers with its value or its own error."""
    found = await reads.read_many(session, node.node_id, body.refs)
    items = [BatchReadItem(ref=ref, ok=False, error=problem_body(result, f"{request.url.path}#{ref}"))
             if isinstance(result, DriveBenchError) else BatchReadItem(ref=ref, ok=True, value=value_out(result))
             for ref, result in zip(body.refs, found, strict=True)]
    return BatchReadOut(node_id=node.node_id, items=items)


@router.put(NODE + "/parameters/{ref:path}", response_model=WriteOut,
            responses={428: {"description": "A write that can make the drive move, without the confirmation naming "
                                            "the node"}})
async def write_parameter(request: Request, session: SessionDep, node: NodeDep, ref: str,
                          body: ParameterWrite, ctx: WriteCtxDep) -> WriteOut:
    """Write and read back. A write the profile marks as moving the drive needs ``confirm`` (the node id) and
    arms the keep-alive guard: this client must then POST ``/api/sessions/{session}/keepalive`` at least every
    2 s, or the drive is quick-stopped. A control word that only stops the drive is never refused."""
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    value = writes.given_value(node, ref, body.value, body.raw)
    result = await writes.write(session, node.node_id, ref, value, ctx=ctx, check=body.check, verify=body.verify)
    return write_out(result, node.pending_reset)


@router.post(NODE + "/parameters:write", response_model=BatchWriteOut,
             responses={422: {"description": "An item does not validate: nothing was written ('items' says which)"},
                        428: {"description": "A write that can make the drive move, without the confirmation naming "
                                            "the node: nothing was written"}})
async def write_parameters(request: Request, session: SessionDep, node: NodeDep, body: BatchWrite,
                           ctx: WriteCtxDep) -> Any:
    """Write many values in one request: all are validated first (one invalid refuses the batch, each item's problem
    in words), a batch with a moving write needs ``confirm`` like the single write; then each is written in order
    through the single write's path (lease, keep-alive guard, one audit row, read-back) until the first error."""
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    wanted = [Wanted(entry.ref, entry.value, entry.raw) for entry in body.items]
    try:
        outcomes = await batch.write_many(session, node.node_id, wanted, ctx=ctx, check=body.check,
                                         verify=body.verify)
    except batch.BatchInvalid as exc:
        problem = problem_body(exc, request.url.path)
        problem["items"] = [{"ref": entry.ref, "ok": error is None,
                             "error": None if error is None else problem_body(error, f"{request.url.path}#{entry.ref}")}
                            for entry, error in zip(body.items, exc.problems, strict=True)]
        return JSONResponse(problem, status_code=422, media_type="application/problem+json")
    items = [BatchWriteItem(ref=outcome.ref, ok=outcome.state is batch.State.WRITTEN, state=outcome.state.value,
                            result=write_out(outcome.result, node.pending_reset) if outcome.result else None,
                            error=problem_body(outcome.error, f"{request.url.path}#{outcome.ref}")
                            if outcome.error else None)
             for outcome in outcomes]
    written = sum(item.ok for item in items)
    return BatchWriteOut(node_id=node.node_id, complete=written == len(items), written=written, items=items,
                         pending_reset=sorted(node.pending_reset))


@router.get(NODE + "/changed-from-default", response_model=ComparisonOut)
async def changed_from_default(session: SessionDep, node: NodeDep,
                               read: Annotated[factory_compare.Reading, Query(description=(
                                   "all: read every setting now; missing: read those not read yet (default); "
                                   "none: compare the values last read"))] = factory_compare.Reading.MISSING,
                               ) -> ComparisonOut:
    """The comparison with the factory setting: the settings (readable, writable, not process data) whose value
    differs from the factory value, and apart from them those whose profile gives no factory value."""
    return comparison_out(await factory_compare.compare(session, node.node_id, read))


@router.post("/audit/{entry_id}/undo", response_model=UndoOut,
             responses={409: {"description": "The record cannot be undone: no old value, its write failed, or the "
                                             "node is gone or handled with another profile (``detail`` says which)"},
                        428: {"description": "The old value can make the drive move: confirm as for a write"}})
async def undo_write(request: Request, entry_id: int, ctx: WriteCtxDep, body: UndoRequest | None = None) -> UndoOut:
    """Write the record's old value back through the checked write (range, confirmation, lease, read-back), logged
    with the origin ``undo <entry_id>``."""
    record = undoing.record(entry_id, settings.database_url)
    state = app_state(request.app)
    session = state.manager.get(record.session_id)
    ctx = ctx.confirming(confirmation(request, body and body.confirm, body and body.confirm_values))
    result = await undoing.undo(session, record, ctx=ctx)
    pending = session.node(record.node_id).pending_reset
    return UndoOut(**write_out(result, pending).model_dump(), undone=entry_id, session_id=session.id,
                   node_id=record.node_id)


@router.post(NODE + "/read-all", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED)
async def read_all(root: RootDep, session: SessionDep, node: NodeDep, jobs: JobsDep, ctx: WriteCtxDep) -> JobOut:
    return job_out(read_jobs.start_read(session, [node.node_id], jobs, ctx=ctx), with_result=False, root=root)


@router.post(NODE + "/read-group", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED)
async def read_group(root: RootDep, session: SessionDep, node: NodeDep, jobs: JobsDep, body: GroupRead,
                     ctx: WriteCtxDep) -> JobOut:
    return job_out(read_jobs.start_read(session, [node.node_id], jobs, ctx=ctx, group=body.group), with_result=False,
                   root=root)


@router.post("/sessions/{session_id}/read-all", response_model=JobOut,
             status_code=status.HTTP_202_ACCEPTED)
async def read_all_nodes(root: RootDep, session: SessionDep, jobs: JobsDep, ctx: WriteCtxDep,
                         body: SessionRead | None = None) -> JobOut:
    """Every node of the session in parallel (each node over its SDO channels)."""
    node_ids = (body.node_ids if body and body.node_ids else
                [n.node_id for n in session.nodes.values() if n.profile is not None])
    return job_out(read_jobs.start_read(session, node_ids, jobs, ctx=ctx), with_result=False, root=root)


@router.post(NODE + "/commands/{command}", response_model=CommandOut)
async def device_command(session: SessionDep, node: NodeDep, command: DeviceCommand, ctx: WriteCtxDep) -> CommandOut:
    result = await device_commands.command(session, node.node_id, command, ctx=ctx)
    return CommandOut(command=result.command.value, via=result.via, detail=shown(result.detail),
                      pending_reset=sorted(node.pending_reset))


@router.get("/sessions/{session_id}/sdo-settings", response_model=SdoSettingsModel)
async def get_sdo_settings(session: SessionDep) -> SdoSettingsModel:
    settings = session_part.service(session).settings
    return SdoSettingsModel(timeout_s=settings.timeout_s, retries=settings.retries, use_sdo2=settings.use_sdo2)


@router.put("/sessions/{session_id}/sdo-settings", response_model=SdoSettingsModel)
async def put_sdo_settings(session: SessionDep, body: SdoSettingsModel) -> SdoSettingsModel:
    session_part.configure(session, SdoSettings(body.timeout_s, body.retries, body.use_sdo2))
    return body


@router.get("/jobs/{job_id}", response_model=JobOut)
async def get_job(root: RootDep, job_id: str, jobs: JobsDep) -> JobOut:
    return job_out(jobs.get(job_id), root=root)


@router.delete("/jobs/{job_id}", response_model=JobOut)
async def cancel_job(root: RootDep, job_id: str, jobs: JobsDep) -> JobOut:
    """Cancel a running job; what it read so far stays in its result."""
    job = jobs.cancel(job_id)
    await job.wait()
    return job_out(job, root=root)
