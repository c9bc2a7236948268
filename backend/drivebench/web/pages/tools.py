"""The Tools screen: DIP-switch calculator, network planner and cable planner (htmx blocks of tools.html)."""

from __future__ import annotations

import asyncio
import re
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response
from starlette.datastructures import FormData, UploadFile

from drivebench.device.calculators.bus_devices import BusDevices
from drivebench.device.calculators.cable import (
    CROSS_SECTIONS_MM2,
    REPEATER_2176_REDUCTION_M,
    SEGMENT_LENGTH_M,
    TOTAL_LENGTH_M,
    plan_cable,
    selection_example,
)
from drivebench.device.calculators.cobids import STANDARD_IDS, channels_of, default_channels, uses_alternative
from drivebench.device.calculators.dip import decode, encode
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.planning.planned_networks import PlannedNetworkStore, compare_with_session
from drivebench.services.planning.planner import CableInput, NetworkPlan, PlannedNode, check_plan
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import StateDep
from drivebench.web.dip_answer import dip_answer
from drivebench.web.problems import error_fragment, problem_body, status_for
from drivebench.web.state import AppState
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)

PAGE = "tools.html"
BAUD_RATES = [1000, 800, 500, 250, 125, 50, 20, 10]


def _devices(state: AppState) -> BusDevices:
    """Every loaded profile (built-in or uploaded): the calculator's devices are those with a ``switches`` section
    (one per key), the planner's every CANopen profile."""
    return BusDevices(state.registry.all())


def _first_key(devices: BusDevices) -> str:
    every = devices.switches.all()
    if not every:
        raise InvalidValue(_("No loaded profile has a 'switches' section: the calculator has no device."))
    return every[0].spec.key


def _int(form: FormData, key: str, label: str) -> int | None:
    value = str(form.get(key) or "").strip()
    if not value:
        return None
    try:
        return int(value, 0)
    except ValueError as exc:
        raise InvalidValue(_("{label}: '{value}' is not a number.").format(label=label, value=value)) from exc


def _error(request: Request, exc: DriveBenchError) -> str:
    return error_fragment(problem_body(exc, str(request.url.path)))


def _render(request: Request, context: dict[str, Any], block: str, status: int = 200) -> Response:
    return templates.TemplateResponse(request, PAGE, context, block_name=block, status_code=status)


def _base(devices: BusDevices, **extra: Any) -> dict[str, Any]:
    families = {device.spec.key: device.spec for device in devices.switches.all()}
    planned = devices.all()
    return {"active": "tools", "families": families, "find_device": devices.find, "channels_of": channels_of,
            "baud_rates": BAUD_RATES, "short_names": {key: spec.short_name for key, spec in families.items()},
            "plan_names": {device.spec.key: device.spec.short_name for device in planned},
            "no_dip": [device.spec.name for device in planned if not device.has_switches],
            "not_on_can": [profile.identity.product_name for profile in devices.not_on_can()],
            "cross_sections": CROSS_SECTIONS_MM2, **extra}


# --- DIP-switch calculator -------------------------------------------------------------------------------------
def _dip_context(request: Request, devices: BusDevices, family: str,
                 form: FormData | None = None) -> tuple[dict[str, Any], int]:
    device = devices.switch_device(family)
    spec = device.spec
    form = form or FormData()
    on = {str(v) for v in form.getlist("on")}
    wanted = str(form.get("pdo_ids") or STANDARD_IDS)
    pdo_ids = wanted if uses_alternative(spec, wanted) else STANDARD_IDS
    fields = {key: str(form.get(key) or "") for key in ("node_id", "baud_kbit", "code_node_id", "code_baud_kbit")}
    error, status = None, 200
    toggle = form.get("toggle")
    if toggle:
        on ^= {str(toggle)}
    try:
        if form.get("action") == "encode":
            node_id, baud = _int(form, "node_id", _("Node address")), _int(form, "baud_kbit", _("Baud rate"))
            if node_id is None or baud is None:
                raise InvalidValue(_("Enter a node address and a baud rate."))
            result = encode(device, node_id, baud)
            on = {label for label, state in result.switches.items() if state}
        else:
            result = decode(device, dict.fromkeys(on, True),
                            code_node_id=_int(form, "code_node_id", spec.node_parameter.code),
                            code_baud_kbit=_int(form, "code_baud_kbit", spec.baud_parameter.code))
    except DriveBenchError as exc:
        error, status = _error(request, exc), status_for(exc)
        result = decode(device, dict.fromkeys(on, True))
    answer = dip_answer(device, result, pdo_ids)
    if error is None:  # the node-address form always shows what the switches give
        fields["node_id"] = "" if result.node_id is None else str(result.node_id)
        fields["baud_kbit"] = "" if result.baud_kbit is None else str(result.baud_kbit)
    code_values = next((s.values for s in spec.settings if s.code == spec.baud_parameter.code), {})
    baud_code_values = {kbit: value for kbit, value in code_values.items() if value is not None and value != kbit}
    return _base(devices, spec=spec, answer=answer, on=on, fields=fields, pdo_ids=pdo_ids, dip_error=error,
                 baud_code_values=baud_code_values), status


@router.get("/tools", response_class=HTMLResponse)
async def tools_page(request: Request, state: StateDep, family: str | None = None) -> Response:
    devices = _devices(state)
    first = _first_key(devices)
    dip_context, _status = _dip_context(request, devices, family or first)
    plan = NetworkPlan(name="Line 1", nodes=[
        PlannedNode(name="Conveyor", device=first, node_id=1, baud_kbit=500),
        PlannedNode(name="Lift", device=first, node_id=2, baud_kbit=500)])
    saved = await asyncio.to_thread(PlannedNetworkStore().list)
    context = {**dip_context, **_cable_context(request, devices, None),
               **_plan_context(plan, state, devices, saved=saved)}
    return templates.TemplateResponse(request, PAGE, context)


@router.get("/ui/tools/dip", response_class=HTMLResponse)
async def dip_family(request: Request, state: StateDep, family: str) -> Response:
    context, status = _dip_context(request, _devices(state), family)
    return _render(request, context, "dip", status)


@router.post("/ui/tools/dip", response_class=HTMLResponse)
async def dip_form(request: Request, state: StateDep) -> Response:
    form = await request.form()
    context, status = _dip_context(request, _devices(state), str(form.get("family")), form)
    return _render(request, context, "dip", status)


# --- cable planner ---------------------------------------------------------------------------------------------
def _cable_context(request: Request, devices: BusDevices, form: FormData | None) -> dict[str, Any]:
    values = {"baud_kbit": "125", "cross_section_mm2": "0.5", "nodes": "28", "length_m": "450",
              "repeater_reduction_m": str(REPEATER_2176_REDUCTION_M)}
    if form is not None:
        values.update({k: str(form.get(k) or "").strip() for k in values})
    plan, error = None, None
    try:
        plan = plan_cable(int(values["baud_kbit"]), float(values["cross_section_mm2"]), int(values["nodes"]),
                          float(values["length_m"]), int(values["repeater_reduction_m"]))
    except ValueError:
        error = _error(request, InvalidValue(_("Enter whole numbers for nodes and repeater reduction, a number "
                                               "for the cable length.")))
    except DriveBenchError as exc:
        error = _error(request, exc)
    return _base(devices, cable=plan, cable_values=values, cable_error=error, total_lengths=TOTAL_LENGTH_M,
                 segment_lengths=SEGMENT_LENGTH_M, cross_sections=CROSS_SECTIONS_MM2,
                 selection_example=selection_example())


@router.post("/ui/tools/cable", response_class=HTMLResponse)
async def cable_form(request: Request, state: StateDep) -> Response:
    context = _cable_context(request, _devices(state), await request.form())
    return _render(request, context, "cable", 422 if context["cable_error"] else 200)


# --- network planner -------------------------------------------------------------------------------------------
def _plan_from_form(form: FormData) -> NetworkPlan:
    nodes = []
    for row in form.getlist("row"):
        def value(key: str, row: Any = row) -> str:
            return str(form.get(f"{key}_{row}") or "").strip()
        label = _("Row {number}").format(number=int(str(row)) + 1)
        node_id = _int(form, f"node_id_{row}", _("{row}, node id").format(row=label))
        baud = _int(form, f"baud_kbit_{row}", label)
        if node_id is None or not 1 <= node_id <= 127:
            raise InvalidValue(_("{row}: node id {node} is not a CANopen node id (1 … 127).").format(
                row=label, node=node_id if node_id is not None else _("(empty)")))
        channels = [str(c) for c in form.getlist(f"channels_{row}")]
        pdo_ids = value("pdo_ids") or STANDARD_IDS
        if not re.fullmatch(r"[a-z0-9][a-z0-9_.-]{0,63}", pdo_ids):
            raise InvalidValue(_("{row}: '{ids}' is not a name of PDO identifiers.").format(row=label, ids=pdo_ids))
        nodes.append(PlannedNode(name=value("name"), device=value("device"), node_id=node_id, baud_kbit=baud or 0,
                                 channels=channels, pdo_ids=pdo_ids))
    cable = None
    length = str(form.get("cable_length_m") or "").strip()
    if length:
        try:
            cable = CableInput(length_m=float(length),
                               cross_section_mm2=float(str(form.get("cable_cross_section_mm2") or 0.5)))
        except ValueError as exc:
            raise InvalidValue(_("Cable length '{length}' is not a number.").format(length=length)) from exc
    return NetworkPlan(name=str(form.get("plan_name") or "").strip() or "Planned network", nodes=nodes, cable=cable)


def _plan_context(plan: NetworkPlan, state: AppState, devices: BusDevices, *, plan_id: int | None = None,
                  saved: list[Any] | None = None, **extra: Any) -> dict[str, Any]:
    rows = []
    for node in plan.nodes:
        device = devices.find(node.device)
        if device is None:
            rows.append({"node": node, "family": node.device, "spec": None, "channels": set()})
            continue
        channels = set(node.channels) if node.channels is not None else default_channels(device.spec)
        rows.append({"node": node, "family": device.spec.key, "spec": device.spec, "channels": channels})
    sessions = [{"id": s.id, "name": s.name} for s in state.manager.list()]
    return _base(devices, plan=plan, plan_id=plan_id, plan_rows=rows, report=check_plan(plan, devices),
                 sessions=sessions, saved=saved if saved is not None else [], **extra)


async def _render_plan(request: Request, plan: NetworkPlan, state: AppState, **extra: Any) -> Response:
    saved = await asyncio.to_thread(PlannedNetworkStore().list)
    return _render(request, _plan_context(plan, state, _devices(state), saved=saved, **extra), "planner")


def _plan_id(form: FormData) -> int | None:
    value = str(form.get("plan_id") or "").strip()
    return int(value) if value.isdigit() else None


async def _form_plan(request: Request) -> tuple[FormData, NetworkPlan]:
    """The plan in the form. A form that cannot be read raises: the error goes beside the action (app.js) and the
    rows stay as typed."""
    form = await request.form()
    return form, _plan_from_form(form)


@router.post("/ui/tools/planner", response_class=HTMLResponse)
async def planner_form(request: Request, state: StateDep) -> Response:
    form, plan = await _form_plan(request)
    action = str(form.get("action") or "check")
    if action == "add":
        last = plan.nodes[-1] if plan.nodes else None
        used = {n.node_id for n in plan.nodes}
        next_id = next((i for i in range(1, 128) if i not in used), 127)
        plan.nodes.append(PlannedNode(device=last.device if last else _first_key(_devices(state)), node_id=next_id,
                                      baud_kbit=last.baud_kbit if last else 500))
    elif action.startswith("remove:"):
        index = int(action.split(":", 1)[1])
        plan.nodes = [n for i, n in enumerate(plan.nodes) if i != index]
    elif action.startswith("device:"):
        index = int(action.split(":", 1)[1])  # device changed: start from that device's factory channels
        plan.nodes[index].channels = None
    elif action == "new":
        plan, form = NetworkPlan(name="Planned network"), FormData()
    return await _render_plan(request, plan, state, plan_id=_plan_id(form))


@router.post("/ui/tools/planner/check", response_class=HTMLResponse)
async def planner_check(request: Request, state: StateDep) -> Response:
    """Findings and COB-IDs of the plan in the form (only that block: the rows stay as the user is typing them)."""
    form, plan = await _form_plan(request)
    return _render(request, _plan_context(plan, state, _devices(state), plan_id=_plan_id(form)), "plan_results")


@router.post("/ui/tools/planner/export")
async def planner_export(request: Request) -> Response:
    plan = _plan_from_form(await request.form())
    filename = "".join(c if c.isalnum() or c in "-_" else "-" for c in plan.name).strip("-") or "network"
    return Response(plan.to_json(), media_type="application/json",
                    headers={"Content-Disposition": f'attachment; filename="{filename}.json"'})


@router.post("/ui/tools/planner/import", response_class=HTMLResponse)
async def planner_import(request: Request, state: StateDep) -> Response:
    """Load a plan JSON file into the editor; a bad file leaves the plan being edited as it was."""
    form = await request.form()
    upload = form.get("plan_file")
    if not isinstance(upload, UploadFile) or not upload.filename:
        raise InvalidValue(_("Choose a plan JSON file to import."))
    plan = NetworkPlan.from_json(await upload.read())
    return await _render_plan(request, plan, state,
                              planner_ok=_("Imported '{name}' from {file} (not saved yet).").format(
                                  name=plan.name, file=upload.filename))


@router.post("/ui/tools/planner/save", response_class=HTMLResponse)
async def planner_save(request: Request, state: StateDep) -> Response:
    form, plan = await _form_plan(request)
    store, plan_id = PlannedNetworkStore(), _plan_id(form)
    saved = await asyncio.to_thread(store.update, plan_id, plan) if plan_id else await asyncio.to_thread(
        store.save, plan)
    return await _render_plan(request, saved.plan, state, plan_id=saved.id,
                              planner_ok=_("Saved '{name}' (#{id}).").format(name=saved.name, id=saved.id))


@router.post("/ui/tools/planner/load/{network_id}", response_class=HTMLResponse)
async def planner_load(request: Request, state: StateDep, network_id: int) -> Response:
    saved = await asyncio.to_thread(PlannedNetworkStore().get, network_id)
    return await _render_plan(request, saved.plan, state, plan_id=saved.id)


@router.post("/ui/tools/planner/delete/{network_id}", response_class=HTMLResponse)
async def planner_delete(request: Request, state: StateDep, network_id: int) -> Response:
    form = await request.form()
    try:
        plan = _plan_from_form(form)
    except DriveBenchError:
        plan = NetworkPlan()
    store = PlannedNetworkStore()
    gone = await asyncio.to_thread(store.get, network_id)
    await asyncio.to_thread(store.delete, network_id)
    plan_id = _plan_id(form)
    return await _render_plan(request, plan or NetworkPlan(), state,
                              plan_id=None if plan_id == network_id else plan_id,
                              planner_ok=_("Deleted '{name}' (#{id}).").format(name=gone.name, id=network_id))


@router.post("/ui/tools/planner/compare", response_class=HTMLResponse)
async def planner_compare(request: Request, state: StateDep) -> Response:
    form, plan = await _form_plan(request)
    session = state.manager.get(str(form.get("session_id") or ""))
    comparison = await compare_with_session(plan, session, _devices(state))
    return await _render_plan(request, plan, state, plan_id=_plan_id(form), comparison=comparison)
