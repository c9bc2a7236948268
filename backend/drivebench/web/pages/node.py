"""The Node screen: tabs Parameters · PDO · Diagnostics · Control · Info for one node of a session.

Each tab is its own template (``node/<tab>.html``) included by ``node.html``; the Parameters tab's parts are
blocks of ``node/parameters.html`` (table rows, one row, the job progress) swapped by htmx. The header shows who
holds the node's write lease (``lease_banner``, polled), with release (the holder) and break (admins).
"""

from __future__ import annotations

import re
from typing import Annotated, Any

from fastapi import APIRouter, Form, Query, Request
from fastapi.responses import HTMLResponse, Response

from drivebench import i18n
from drivebench.device.drive.motion import motion_of
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.number_base import shows_hex
from drivebench.errors import AccessDenied, DriveBenchError, NodeOffline, NotFound, SdoTimeoutError
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.bus.views import node_public
from drivebench.services.monitoring import object_list
from drivebench.services.params import device_commands, lookup, node_lease, read_all, reads, session_part, writes
from drivebench.services.params.device_commands import DeviceCommand
from drivebench.services.params.values import ParameterValue, WriteResult
from drivebench.services.users.principals import Role
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.identity import PrincipalDep
from drivebench.web.pages.node_info import IdentityShown, shown
from drivebench.web.safety import WriteCtxDep, WriterDep, confirmation
from drivebench.web.state import app_state
from drivebench.web.templating import templates

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
TABS = [("parameters", N_("Parameters")), ("pdo", N_("PDO")), ("diagnostics", N_("Diagnostics")),
        ("control", N_("Control")), ("info", N_("Info"))]  # translated where shown (node.html)
UI = "/ui/sessions/{session_id}/nodes/{node_id}"

IDENTITY = [(N_("Device type"), "0x1000"), (N_("Vendor ID"), "0x1018.1"), (N_("Product code"), "0x1018.2"),
            (N_("Revision number"), "0x1018.3"), (N_("Serial number"), "0x1018.4")]  # translated where shown
FIRMWARE_REFS = ["C00099", "C0099", "C0200", "r0018", "0x100A"]


def row_id(ref: str) -> str:
    return "p-" + re.sub(r"[^A-Za-z0-9]+", "-", ref)


def edit_value(last: ParameterValue | None, item: Item) -> str:
    """What the new-value field starts with: the value read last as a user would type it (``50``, not
    ``50.0``; a bit-coded word and a COB-ID in hex)."""
    if last is None or last.value is None:
        return ""
    if isinstance(last.raw, int) and shows_hex(item):  # a bit-coded word, a COB-ID, an identity
        return f"0x{last.raw:X}"
    if isinstance(last.value, float) and last.value.is_integer():
        return str(int(last.value))
    if isinstance(last.value, float):  # 12,5 in German (the value parser reads either mark)
        return str(last.value).replace(".", i18n.decimal_symbol())
    return str(last.value)


templates.env.filters["row_id"] = row_id
templates.env.filters["edit_value"] = edit_value
templates.env.filters["motion"] = motion_of  # rows whose write can move the drive: the page asks first (node.js)


def _base(request: Request, session: Session, node: SessionNode, tab: str, **extra: Any) -> dict[str, Any]:
    return {"active": "plant", "session": session, "node": node, "public": node_public(session, node),
            "sdo_label": session.network.sdo_label(node.node_id),
            "second_sdo_channel": session.network.capabilities.second_sdo_channel,
            "tabs": TABS, "tab": tab, "base": f"/ui/sessions/{session.id}/nodes/{node.node_id}",
            "page": f"/sessions/{session.id}/nodes/{node.node_id}", **extra}


def _parameters_context(session: Session, node: SessionNode, q: str = "", group: str = "",
                        pset: int = 1) -> dict[str, Any]:
    sets = lookup.parameter_sets(node)
    pset = pset if 1 <= pset <= sets else 1
    found = lookup.items(node, q, group or None, pset)
    by_group: dict[str, list[Any]] = {}
    for item in found:
        by_group.setdefault(item.group, []).append(item)
    names = lookup.groups(node)
    names += [name for name in by_group if name not in names]  # an address the profile does not list
    ordered = [(name, by_group[name]) for name in names if name in by_group]
    return {"groups": lookup.groups(node), "grouped": ordered, "q": q, "group": group, "count": len(found),
            "parameter_sets": sets, "pset": pset,
            "values": session_part.service(session).values.get(node.node_id, {}),
            "failures": session_part.service(session).failures.get(node.node_id, {}),
            "settings": session_part.service(session).settings}


def _vendor(node: SessionNode) -> tuple[int | None, str]:
    identity = node.profile.identity if node.profile else None
    return (identity.vendor_id, identity.vendor_name) if identity else (None, "")


def _tab_context(session: Session, node: SessionNode, tab: str) -> dict[str, Any]:
    if tab == "parameters":
        return _parameters_context(session, node)
    if tab == "info":
        return {"identity_rows": [shown(_(label), ref, node.identity.get(key), _vendor(node)) for (label, ref), key in
                                  zip(IDENTITY, ["device_type", "vendor_id", "product_code", "revision", "serial"],
                                      strict=True)]}
    return {}


@router.get("/sessions/{session_id}/nodes/{node_id}", response_class=HTMLResponse)
async def node_page(request: Request, session: SessionDep, node: NodeDep,
                    tab: Annotated[str, Query()] = "parameters") -> Response:
    if tab not in dict(TABS):
        raise NotFound(_("No tab '{tab}' (tabs: {tabs})").format(tab=tab, tabs=", ".join(dict(TABS))))
    context = _base(request, session, node, tab, **_tab_context(session, node, tab))
    return templates.TemplateResponse(request, "node.html", context)


@router.get(UI + "/tabs/{tab}", response_class=HTMLResponse)
async def node_tab(request: Request, session: SessionDep, node: NodeDep, tab: str) -> Response:
    if tab not in dict(TABS):
        raise NotFound(_("No tab '{tab}'").format(tab=tab))
    context = _base(request, session, node, tab, **_tab_context(session, node, tab))
    return templates.TemplateResponse(request, "node.html", context, block_name="tab_body")


@router.get(UI + "/nmt", response_class=HTMLResponse)
async def nmt_badge(request: Request, session: SessionDep, node: NodeDep) -> Response:
    """The header's NMT state badge, polled by itself so it follows NMT commands and heartbeats."""
    context = _base(request, session, node, "parameters")
    return templates.TemplateResponse(request, "node.html", context, block_name="nmt_badge")


# --- write lease banner ----------------------------------------------------------------------------------
def _lease_banner(request: Request, session: Session, node: SessionNode, writer: node_lease.Writer,
                  may_break: bool, note: str = "") -> Response:
    lease = node_lease.leases(session).current(node.node_id)
    context = _base(request, session, node, "parameters", lease=lease, lease_text=lease.text(node.node_id) if lease
                    else "", yours=bool(lease and lease.writer.same(writer)), may_break=may_break, lease_note=note)
    return templates.TemplateResponse(request, "node.html", context, block_name="lease_banner")


@router.get(UI + "/lease", response_class=HTMLResponse)
async def lease_banner(request: Request, session: SessionDep, node: NodeDep, writer: WriterDep,
                       principal: PrincipalDep) -> Response:
    return _lease_banner(request, session, node, writer, principal.may(Role.ADMIN))


@router.post(UI + "/lease/release", response_class=HTMLResponse)
async def release_lease(request: Request, session: SessionDep, node: NodeDep, writer: WriterDep,
                        principal: PrincipalDep) -> Response:
    released = node_lease.leases(session).release(node.node_id, writer)
    return _lease_banner(request, session, node, writer, principal.may(Role.ADMIN),
                         _("Lease released: others may write the node.") if released else "")


@router.post(UI + "/lease/break", response_class=HTMLResponse)
async def break_lease(request: Request, session: SessionDep, node: NodeDep, writer: WriterDep,
                      principal: PrincipalDep) -> Response:
    if not principal.may(Role.ADMIN):
        raise AccessDenied(_("Only an admin may break another writer's lease."))
    broken = node_lease.leases(session).break_lease(node.node_id, f"{principal.name} ({writer.client})")
    return _lease_banner(request, session, node, writer, True,
                         _("Lease of {writer} broken (logged).").format(writer=broken.writer.name))


# --- parameters tab --------------------------------------------------------------------------------------
@router.get(UI + "/parameters", response_class=HTMLResponse)
async def parameter_rows(request: Request, session: SessionDep, node: NodeDep, q: str = "",
                         group: str = "", pset: int = 1) -> Response:
    context = _base(request, session, node, "parameters", **_parameters_context(session, node, q, group, pset))
    return templates.TemplateResponse(request, "node/parameters.html", context, block_name="param_rows")


def _row(request: Request, session: Session, node: SessionNode, ref: str, *,
         result: WriteResult | None = None, transfer: str = "auto") -> Response:
    item = lookup.resolve(node, ref)
    context = _base(request, session, node, "parameters", item=item, result=result, transfer=transfer,
                    values=session_part.service(session).values.get(node.node_id, {}),
                    failures=session_part.service(session).failures.get(node.node_id, {}))
    return templates.TemplateResponse(request, "node/parameters.html", context, block_name="one_row")


@router.post(UI + "/parameters/{ref:path}/read", response_class=HTMLResponse)
async def read_row(request: Request, session: SessionDep, node: NodeDep, ref: str,
                   transfer: Annotated[str, Form(pattern="^(auto|block)$")] = "auto") -> Response:
    """Read one row; ``transfer=block`` (the row's Block button on strings) reads by CiA 301 block upload."""
    await reads.read(session, node.node_id, ref, transfer=transfer)
    return _row(request, session, node, ref, transfer=transfer)


@router.post(UI + "/parameters/{ref:path}/write", response_class=HTMLResponse)
async def write_row(request: Request, session: SessionDep, node: NodeDep, ref: str, ctx: WriteCtxDep,
                    value: Annotated[str, Form()], confirm: Annotated[str | None, Form()] = None,
                    confirm_values: Annotated[str | None, Form()] = None) -> Response:
    """A row the profile marks as moving the drive sends ``confirm`` and ``confirm_values`` after the page's
    question (see the row)."""
    result = await writes.write(session, node.node_id, ref, value,
                                 ctx=ctx.confirming(confirmation(request, confirm or None, confirm_values or None)))
    return _row(request, session, node, ref, result=result)


@router.post(UI + "/read", response_class=HTMLResponse)
async def start_read(request: Request, session: SessionDep, node: NodeDep, ctx: WriteCtxDep,
                     group: Annotated[str, Form()] = "", pset: Annotated[int, Form()] = 1) -> Response:
    job = read_all.start_read(session, [node.node_id], app_state(request.app).jobs, ctx=ctx, group=group or None,
                             parameter_set=pset if 1 <= pset <= lookup.parameter_sets(node) else 1)
    context = _base(request, session, node, "parameters", job=job)
    return templates.TemplateResponse(request, "node/parameters.html", context, block_name="job_progress")


@router.post(UI + "/commands/{command}", response_class=HTMLResponse)
async def run_command(request: Request, session: SessionDep, node: NodeDep, command: DeviceCommand,
                      ctx: WriteCtxDep) -> Response:
    result = await device_commands.command(session, node.node_id, command, ctx=ctx)
    context = _base(request, session, node, "parameters", command_result=result)
    return templates.TemplateResponse(request, "node/parameters.html", context, block_name="command_result")


@router.post(UI + "/sdo-settings", response_class=HTMLResponse)
async def sdo_settings(request: Request, session: SessionDep, node: NodeDep,
                       timeout_ms: Annotated[int, Form(ge=10, le=30000)],
                       retries: Annotated[int, Form(ge=0, le=10)], use_sdo2: Annotated[str, Form()] = "") -> Response:
    session_part.configure(session, session_part.SdoSettings(timeout_ms / 1000, retries, bool(use_sdo2)))
    context = _base(request, session, node, "parameters", settings=session_part.service(session).settings, saved=True)
    return templates.TemplateResponse(request, "node/parameters.html", context, block_name="sdo_settings")


# --- info tab --------------------------------------------------------------------------------------------
@router.post(UI + "/info/object-list", response_class=HTMLResponse)
async def read_object_list(request: Request, session: SessionDep, node: NodeDep) -> Response:
    """The slave's object list through the CoE SDO information service, compared with its profile."""
    objects = await object_list.compare(session, node.node_id)
    context = _base(request, session, node, "info", objects=objects)
    return templates.TemplateResponse(request, "node/info.html", context, block_name="object_list")


@router.post(UI + "/info/read", response_class=HTMLResponse)
async def read_info(request: Request, session: SessionDep, node: NodeDep) -> Response:
    rows: list[IdentityShown] = []
    for label, ref in IDENTITY:
        try:
            value = await reads.read(session, node.node_id, ref)
            row = (shown(_(label), ref, value.raw, _vendor(node)) if isinstance(value.raw, int)
                   else IdentityShown(_(label), ref, value.display, ""))
        except SdoTimeoutError as exc:
            raise NodeOffline(_("Node {node} does not answer: {problem}").format(
                node=node.node_id, problem=exc.shown_detail())) from exc
        except DriveBenchError as exc:
            row = IdentityShown(_(label), ref, f"– ({_(exc.title)})", "")
        rows.append(row)
    for ref in FIRMWARE_REFS:
        try:
            value = await reads.read(session, node.node_id, ref)
        except DriveBenchError:
            continue
        rows.append(IdentityShown(_("Firmware / software"), value.ref, value.display, ""))
        break
    context = _base(request, session, node, "info", live_rows=rows)
    return templates.TemplateResponse(request, "node/info.html", context, block_name="identity_live")
