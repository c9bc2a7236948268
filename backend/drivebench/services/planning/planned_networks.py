"""Saved network plans: save, list, load, delete, JSON export/import, and comparison with a live bus scan."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import UTC, datetime
from typing import Literal

from pydantic import BaseModel
from sqlalchemy import select
from sqlalchemy.orm import Session as DbSession

from drivebench.device.calculators.bus_devices import BusDevices
from drivebench.device.calculators.dip import SwitchDevices
from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.planning.planner import NetworkPlan, PlannedNode
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import PlannedNetworkRow, utcnow


class PlannedNetworkSummary(BaseModel):
    id: int
    name: str
    created: datetime
    updated: datetime
    node_count: int


class PlannedNetwork(PlannedNetworkSummary):
    plan: NetworkPlan


def _aware(moment: datetime) -> datetime:
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)  # SQLite drops the zone; we store UTC


def _summary(row: PlannedNetworkRow) -> PlannedNetworkSummary:
    return PlannedNetworkSummary(id=row.id, name=row.name, created=_aware(row.created), updated=_aware(row.updated),
                                 node_count=len(row.body.get("nodes", [])))


def _full(row: PlannedNetworkRow) -> PlannedNetwork:
    return PlannedNetwork(**_summary(row).model_dump(), plan=NetworkPlan.model_validate(row.body))


class PlannedNetworkStore:
    """Planned networks in the database at ``url`` (default: ``settings.database_url``)."""

    def __init__(self, url: str | None = None) -> None:
        self.url = url

    def save(self, plan: NetworkPlan) -> PlannedNetwork:
        with transaction(self.url) as db:
            row = PlannedNetworkRow(name=plan.name, body=plan.model_dump(mode="json"))
            db.add(row)
            db.flush()
            return _full(row)

    def update(self, network_id: int, plan: NetworkPlan) -> PlannedNetwork:
        with transaction(self.url) as db:
            row = self._row(db, network_id)
            row.name = plan.name
            row.body = plan.model_dump(mode="json")
            row.updated = utcnow()
            db.flush()
            return _full(row)

    def list(self) -> list[PlannedNetworkSummary]:
        with transaction(self.url) as db:
            rows = db.scalars(select(PlannedNetworkRow).order_by(PlannedNetworkRow.name, PlannedNetworkRow.id))
            return [_summary(row) for row in rows]

    def get(self, network_id: int) -> PlannedNetwork:
        with transaction(self.url) as db:
            return _full(self._row(db, network_id))

    def delete(self, network_id: int) -> None:
        with transaction(self.url) as db:
            db.delete(self._row(db, network_id))

    def export_json(self, network_id: int) -> str:
        return self.get(network_id).plan.to_json()

    def import_json(self, text: str | bytes) -> PlannedNetwork:
        """Store a plan exported before. The text is checked first: bad JSON raises InvalidValue, nothing stored."""
        return self.save(NetworkPlan.from_json(text))

    @staticmethod
    def _row(db: DbSession, network_id: int) -> PlannedNetworkRow:
        row = db.get(PlannedNetworkRow, network_id)
        if row is None:
            raise NotFound(_("Planned network {id} does not exist (deleted, or saved in another database).").format(
                id=network_id))
        return row


# --- comparison with a live scan ------------------------------------------------------------------------------
NodeStatus = Literal["ok", "wrong_device", "unverified", "missing", "extra"]


class NodeCheck(BaseModel):
    node_id: int
    status: NodeStatus
    planned: PlannedNode | None = None
    found_device: str | None = None
    """Product name of the profile the scan matched (0x1018 vendor id / product code)."""
    found_profile: str | None = None
    identity: dict[str, int] | None = None
    message: str


class LiveComparison(BaseModel):
    plan_name: str
    session_id: str
    session_name: str
    ok: bool
    """Every planned node answered as the planned device and no other node answered."""
    counts: dict[NodeStatus, int]
    nodes: list[NodeCheck]


def _check_found(planned: PlannedNode, found: SessionNode, devices: BusDevices | SwitchDevices) -> NodeCheck:
    device = devices.find(planned.device)
    planned_name = device.spec.name if device else planned.device
    profile = found.profile
    base = {"node_id": planned.node_id, "planned": planned, "identity": dict(found.identity) or None,
            "found_profile": profile.id if profile else None,
            "found_device": profile.identity.product_name if profile else None}
    if profile is not None:
        same_switches = device is not None and profile.switches is not None and profile.switches.key == device.spec.key
        if same_switches or (device is not None and profile.id in device.profile_ids):
            return NodeCheck(status="ok", message=_("Answers as {device}.").format(
                device=profile.identity.product_name), **base)
        return NodeCheck(status="wrong_device", **base,
                         message=_("Answers as {device}, planned: {planned}.").format(
                             device=profile.identity.product_name, planned=planned_name))
    vendor = found.identity.get("vendor_id")
    expected = device.vendor_id if device else None
    if vendor is not None and expected is not None and vendor != expected:
        return NodeCheck(status="wrong_device", **base,
                         message=_("Vendor id {vendor} is not the planned device's ({expected}).").format(
                             vendor=f"0x{vendor:08X}", expected=f"0x{expected:08X}"))
    ident = ", ".join(f"{k} 0x{v:08X}" for k, v in found.identity.items()) or _("identity 0x1018 not readable")
    return NodeCheck(status="unverified", **base,
                     message=_("Answers, but no device profile matches its identity ({identity}).").format(
                         identity=ident))


def compare_live(plan: NetworkPlan, answered: Iterable[SessionNode], devices: BusDevices | SwitchDevices, *,
                 session_id: str = "", session_name: str = "") -> LiveComparison:
    """Which planned nodes answered (as the planned device), which are missing, which extra nodes appeared."""
    found = {node.node_id: node for node in answered}
    planned_ids = {node.node_id for node in plan.nodes}
    checks: list[NodeCheck] = []
    for planned in plan.nodes:
        if planned.node_id in found:
            checks.append(_check_found(planned, found[planned.node_id], devices))
        else:
            checks.append(NodeCheck(node_id=planned.node_id, status="missing", planned=planned,
                                    message=_("No answer to the scan (SDO 0x1000 / heartbeat).")))
    for node_id in sorted(set(found) - planned_ids):
        node = found[node_id]
        name = node.profile.identity.product_name if node.profile else _("unknown device")
        checks.append(NodeCheck(node_id=node_id, status="extra", identity=dict(node.identity) or None,
                                found_profile=node.profile.id if node.profile else None,
                                found_device=node.profile.identity.product_name if node.profile else None,
                                message=_("Not in the plan; answers as {device}.").format(device=name)))
    checks.sort(key=lambda c: c.node_id)
    counts: dict[NodeStatus, int] = {s: 0 for s in ("ok", "wrong_device", "unverified", "missing", "extra")}
    for check in checks:
        counts[check.status] += 1
    return LiveComparison(plan_name=plan.name, session_id=session_id, session_name=session_name,
                          ok=counts["ok"] == len(plan.nodes) and counts["extra"] == 0, counts=counts, nodes=checks)


async def compare_with_session(plan: NetworkPlan, session: Session, devices: BusDevices | SwitchDevices,
                               timeout_s: float = 0.5) -> LiveComparison:
    """Scan ``session``'s bus and compare the nodes that answered with ``plan``."""
    answered = await session.scan(timeout_s)
    return compare_live(plan, answered, devices, session_id=session.id, session_name=session.name)
