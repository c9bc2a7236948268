"""The Tools screen: DIP-switch calculator, cable planner and network planner (htmx blocks of tools.html)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response
from starlette.datastructures import FormData, UploadFile

from drivebench.device.cable import CROSS_SECTIONS_MM2, SEGMENT_LENGTH_M, SELECTION_EXAMPLE, TOTAL_LENGTH_M
from drivebench.device.cobids import channels_of, default_channels
from drivebench.device.dip import FAMILIES, LENZE_8400_MOTEC, SIEMENS_MM4, decode, encode, family_spec
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.services.planner import CableInput, NetworkPlan, PlannedNode, check_plan, compare_with_scan
from drivebench.web.api.tools import dip_answer
from drivebench.web.deps import StateDep
from drivebench.web.problems import error_fragment, problem_body
from drivebench.web.templating import templates

router = APIRouter(include_in_schema=False)

PAGE = "tools.html"


def _int(form: FormData, key: str) -> int | None:
    value = str(form.get(key) or "").strip()
    if not value:
        return None
    try:
        return int(value, 0)
    except ValueError as exc:
        raise InvalidValue(f"{key.replace('_', ' ')}: '{value}' is not a number.") from exc


def _error(request: Request, exc: DriveBenchError) -> str:
    return error_fragment(problem_body(exc, str(request.url.path)))


def _base(**extra: Any) -> dict[str, Any]:
    return {"active": "tools", "families": FAMILIES, "lenze_8400": LENZE_8400_MOTEC, "mm4": SIEMENS_MM4,
            "channels_of": channels_of, **extra}


# --- DIP-switch calculator ---------------------------------------------------------------------------------
def _dip_context(request: Request, family: str, form: FormData | None = None) -> dict[str, Any]:
    spec = family_spec(family)
    form = form or FormData()
    on = {str(v) for v in form.getlist("on")}
    pdo_ids = "lenze" if form.get("pdo_ids") == "lenze" and spec.key == LENZE_8400_MOTEC else "canopen"
    fields = {"node_id": str(form.get("node_id") or ""), "baud_kbit": str(form.get("baud_kbit") or ""),
              "code_node_id": str(form.get("code_node_id") or ""),
              "code_baud_kbit": str(form.get("code_baud_kbit") or "")}
    error = None
    toggle = form.get("toggle")
    if toggle:
        on ^= {str(toggle)}
    try:
        if form.get("action") == "encode":
            node_id, baud = _int(form, "node_id"), _int(form, "baud_kbit")
            if node_id is None or baud is None:
                raise InvalidValue("Enter a node id and a baud rate.")
            result = encode(spec.key, node_id, baud)
            on = {label for label, state in result.switches.items() if state}
        else:
            result = decode(spec.key, dict.fromkeys(on, True), code_node_id=_int(form, "code_node_id"),
                            code_baud_kbit=_int(form, "code_baud_kbit"))
    except DriveBenchError as exc:
        error = _error(request, exc)
        result = decode(spec.key, dict.fromkeys(on, True))
    answer = dip_answer(result, pdo_ids)  # type: ignore[arg-type]
    if error is None:  # the node-id/baud form always shows what the switches give
        fields["node_id"] = "" if result.node_id is None else str(result.node_id)
        fields["baud_kbit"] = "" if result.baud_kbit is None else str(result.baud_kbit)
    return _base(spec=spec, answer=answer, on=on, fields=fields, pdo_ids=pdo_ids, dip_error=error)


@router.get("/tools", response_class=HTMLResponse)
async def tools_page(request: Request, state: StateDep, family: str = LENZE_8400_MOTEC) -> Response:
    plan = NetworkPlan(nodes=[PlannedNode(name="Conveyor", device=LENZE_8400_MOTEC, node_id=1, baud_kbit=500),
                              PlannedNode(name="Lift", device=LENZE_8400_MOTEC, node_id=2, baud_kbit=500)])
    context = {**_dip_context(request, family), **_cable_context(request, None), **_plan_context(plan, state)}
    return templates.TemplateResponse(request, PAGE, context)


@router.get("/ui/tools/dip", response_class=HTMLResponse)
async def dip_family(request: Request, family: str) -> Response:
    return templates.TemplateResponse(request, PAGE, _dip_context(request, family), block_name="dip")


@router.post("/ui/tools/dip", response_class=HTMLResponse)
async def dip_form(request: Request) -> Response:
    form = await request.form()
    return templates.TemplateResponse(request, PAGE, _dip_context(request, str(form.get("family")), form),
                                      block_name="dip")


# --- cable planner -----------------------------------------------------------------------------------------
def _cable_context(request: Request, form: FormData | None) -> dict[str, Any]:
    from drivebench.device.cable import plan_cable

    values = {"baud_kbit": "125", "cross_section_mm2": "0.5", "nodes": "28", "length_m": "450",
              "repeater_reduction_m": "30"}
    if form is not None:
        values.update({k: str(form.get(k) or "") for k in values})
    plan, error = None, None
    try:
        plan = plan_cable(int(values["baud_kbit"]), float(values["cross_section_mm2"]), int(values["nodes"]),
                          float(values["length_m"]), int(values["repeater_reduction_m"]))
    except ValueError:
        error = _error(request, InvalidValue("Enter numbers for nodes, length and repeater reduction."))
    except DriveBenchError as exc:
        error = _error(request, exc)
    return _base(cable=plan, cable_values=values, cable_error=error, total_lengths=TOTAL_LENGTH_M,
                 segment_lengths=SEGMENT_LENGTH_M, cross_sections=CROSS_SECTIONS_MM2,
                 selection_example=SELECTION_EXAMPLE)


@router.post("/ui/tools/cable", response_class=HTMLResponse)
async def cable_form(request: Request) -> Response:
    context = _cable_context(request, await request.form())
    return templates.TemplateResponse(request, PAGE, context, block_name="cable")


# --- network planner ---------------------------------------------------------------------------------------
def _plan_from_form(form: FormData) -> NetworkPlan:
    rows = form.getlist("row")
    nodes = []
    for row in rows:
        def value(key: str, row: Any = row) -> str:
            return str(form.get(f"{key}_{row}") or "").strip()
        try:
            node_id, baud = int(value("node_id") or 0), int(value("baud_kbit") or 0)
        except ValueError as exc:
            raise InvalidValue(f"Row {int(str(row)) + 1}: node id and baud rate must be numbers.") from exc
        if not 1 <= node_id <= 127:
            raise InvalidValue(f"Row {int(str(row)) + 1}: node id {node_id} is not a CANopen node id (1 … 127).")
        channels = [str(c) for c in form.getlist(f"channels_{row}")]
        nodes.append(PlannedNode(name=value("name"), device=value("device"), node_id=node_id, baud_kbit=baud,
                                 channels=channels, pdo_ids="lenze" if value("pdo_ids") == "lenze" else "canopen"))
    cable = None
    length = str(form.get("cable_length_m") or "").strip()
    if length:
        try:
            cable = CableInput(length_m=float(length),
                               cross_section_mm2=float(str(form.get("cable_cross_section_mm2") or 0.5)))
        except ValueError as exc:
            raise InvalidValue(f"Cable length '{length}' is not a number.") from exc
    return NetworkPlan(name=str(form.get("plan_name") or "Planned network"), nodes=nodes, cable=cable)


def _plan_context(plan: NetworkPlan, state: Any, **extra: Any) -> dict[str, Any]:
    rows = []
    for node in plan.nodes:
        try:
            family = family_spec(node.device).key
            channels = set(node.channels) if node.channels is not None else default_channels(family)
        except DriveBenchError:
            family, channels = node.device, set()
        rows.append({"node": node, "family": family, "channels": channels})
    sessions = [{"id": s.id, "name": s.name} for s in state.manager.list()]
    return _base(plan=plan, plan_rows=rows, report=check_plan(plan), sessions=sessions, **extra)


def _render_plan(request: Request, plan: NetworkPlan, state: Any, **extra: Any) -> Response:
    return templates.TemplateResponse(request, PAGE, _plan_context(plan, state, **extra), block_name="planner")


@router.post("/ui/tools/planner", response_class=HTMLResponse)
async def planner_form(request: Request, state: StateDep) -> Response:
    form = await request.form()
    try:
        plan = _plan_from_form(form)
    except DriveBenchError as exc:
        return _render_plan(request, NetworkPlan(), state, planner_error=_error(request, exc))
    action = str(form.get("action") or "check")
    if action == "add":
        last = plan.nodes[-1] if plan.nodes else None
        used = {n.node_id for n in plan.nodes}
        next_id = next(i for i in range(1, 128) if i not in used) if len(used) < 127 else 127
        plan.nodes.append(PlannedNode(device=last.device if last else LENZE_8400_MOTEC, node_id=next_id,
                                      baud_kbit=last.baud_kbit if last else 500))
    elif action.startswith("remove:"):
        index = int(action.split(":", 1)[1])
        plan.nodes = [n for i, n in enumerate(plan.nodes) if i != index]
    elif action.startswith("device:"):
        index = int(action.split(":", 1)[1])  # device changed: start from that device's factory channels
        plan.nodes[index].channels = None
    return _render_plan(request, plan, state)


@router.post("/ui/tools/planner/export")
async def planner_export(request: Request) -> Response:
    plan = _plan_from_form(await request.form())
    filename = "".join(c if c.isalnum() or c in "-_" else "-" for c in plan.name).strip("-") or "network"
    return Response(plan.to_json(), media_type="application/json",
                    headers={"Content-Disposition": f'attachment; filename="{filename}.json"'})


@router.post("/ui/tools/planner/import", response_class=HTMLResponse)
async def planner_import(request: Request, state: StateDep) -> Response:
    form = await request.form()
    upload = form.get("plan_file")
    if not isinstance(upload, UploadFile):
        return _render_plan(request, NetworkPlan(), state,
                            planner_error=_error(request, InvalidValue("Choose a plan JSON file to import.")))
    try:
        plan = NetworkPlan.from_json(await upload.read())
    except DriveBenchError as exc:
        return _render_plan(request, NetworkPlan(), state, planner_error=_error(request, exc))
    return _render_plan(request, plan, state)


@router.post("/ui/tools/planner/compare", response_class=HTMLResponse)
async def planner_compare(request: Request, state: StateDep) -> Response:
    form = await request.form()
    plan = _plan_from_form(form)
    try:
        session = state.manager.get(str(form.get("session_id") or ""))
        await session.scan()
    except DriveBenchError as exc:
        return _render_plan(request, plan, state, planner_error=_error(request, exc))
    found = {node.node_id: (node.identity or None) for node in session.nodes.values()}
    return _render_plan(request, plan, state, comparison=compare_with_scan(plan, found), compared_with=session.name)
