"""Line projects on the server: made from a planned network, stored, and opened from a file, which recreates the
planned network, the parameter sets and the profile references (an embedded uploaded profile is loaded, a missing
one is named in words)."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from datetime import UTC, datetime

from pydantic import BaseModel, Field
from sqlalchemy import select

from drivebench.device.calculators.bus_devices import BusDevices
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Profile
from drivebench.errors import DriveBenchError, NotFound
from drivebench.i18n import _
from drivebench.services.line.project import (
    PDO_INDICES,
    EmbeddedProfile,
    ExpectedIdentity,
    LineProject,
    ProfileRef,
    ProjectNode,
    ProjectSet,
    Values,
)
from drivebench.services.planning.planned_networks import PlannedNetworkStore
from drivebench.services.planning.planner import NetworkPlan
from drivebench.services.sets import set_formats
from drivebench.services.sets.parameter_sets import ParameterSetStore, StoredSet, engineering
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import LineProjectRow


class LineProjectSummary(BaseModel):
    id: int
    name: str
    network_id: int | None
    created: datetime
    updated: datetime
    node_count: int


class StoredProject(LineProjectSummary):
    project: LineProject


class OpenedProject(StoredProject):
    notes: list[str] = Field(default_factory=list)
    """What opening it did or could not do, in words (a profile loaded, one missing, one that changed)."""


def _aware(moment: datetime) -> datetime:
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


def _stored(row: LineProjectRow) -> StoredProject:
    project = LineProject.model_validate(row.body)
    return StoredProject(id=row.id, name=row.name, network_id=row.network_id, created=_aware(row.created),
                         updated=_aware(row.updated), node_count=len(project.nodes), project=project)


class LineProjectStore:
    def __init__(self, url: str | None = None) -> None:
        self.url = url

    def save(self, project: LineProject, network_id: int | None) -> StoredProject:
        with transaction(self.url) as db:
            row = LineProjectRow(name=project.name, network_id=network_id, body=project.model_dump(mode="json"))
            db.add(row)
            db.flush()
            return _stored(row)

    def list(self) -> list[LineProjectSummary]:
        with transaction(self.url) as db:
            rows = db.scalars(select(LineProjectRow).order_by(LineProjectRow.name, LineProjectRow.id))
            return [LineProjectSummary(**_stored(row).model_dump(exclude={"project"})) for row in rows]

    def get(self, project_id: int) -> StoredProject:
        with transaction(self.url) as db:
            row = db.get(LineProjectRow, project_id)
            if row is None:
                raise NotFound(_("Line project {id} does not exist (deleted, or saved in another database).").format(
                    id=project_id))
            return _stored(row)

    def delete(self, project_id: int) -> None:
        with transaction(self.url) as db:
            row = db.get(LineProjectRow, project_id)
            if row is None:
                raise NotFound(_("Line project {id} does not exist (deleted, or saved in another database).").format(
                    id=project_id))
            db.delete(row)


# --- profiles -------------------------------------------------------------------------------------------------
def profile_ref(registry: ProfileRegistry, profile_id: str) -> ProfileRef:
    """The profile by id and content hash; an uploaded one with its file, so another server can load it."""
    loaded = registry.loaded(profile_id)
    content = loaded.original if loaded.original is not None else loaded.profile.model_dump_json().encode()
    embedded = None
    if not registry.is_builtin(profile_id):
        embedded = EmbeddedProfile(filename=f"{profile_id}{loaded.suffix}",
                                   content=content.decode("utf-8", errors="replace"))
    return ProfileRef(id=profile_id, sha256=hashlib.sha256(content).hexdigest(), embedded=embedded)


def expected_identity(profile: Profile) -> ExpectedIdentity:
    identity = profile.identity
    return ExpectedIdentity(device_type=identity.device_type, vendor_id=identity.vendor_id,
                            product_code=identity.product_code, revision_min=identity.revision,
                            revision_max=identity.revision)


def split_pdo(profile: Profile, values: Mapping[str, int | float | str]) -> tuple[Values, Values]:
    """A set's values as (the parameter set, the PDO set-up 0x1400-0x1BFF)."""
    catalog = catalog_for(profile)
    settings: Values = {}
    pdo: Values = {}
    for ref, raw in values.items():
        try:
            index = catalog.resolve(ref).index
        except DriveBenchError:
            index = None
        (pdo if index in PDO_INDICES else settings)[ref] = raw
    return settings, pdo


def profile_of_device(registry: ProfileRegistry, device: str) -> Profile | None:
    found = BusDevices(registry.all()).find(device)
    if found is None or not found.profile_ids:
        return None
    return registry.get(found.profile_ids[0])


def build_project(plan: NetworkPlan, registry: ProfileRegistry, sets: Mapping[int, StoredSet], *,
                  optional: set[int] | frozenset[int] = frozenset()) -> LineProject:
    """A project of a planned network: per node the planned device's profile, the identity it states, the set
    chosen for the node (``sets`` by node id)."""
    nodes = []
    for planned in plan.nodes:
        profile = profile_of_device(registry, planned.device)
        stored = sets.get(planned.node_id)
        parameter_set: ProjectSet | None = None
        pdo: Values = {}
        if stored is not None and profile is not None:
            values, pdo = split_pdo(profile, stored.values)
            parameter_set = ProjectSet(name=stored.info.name, set_id=stored.info.id, values=values)
        nodes.append(ProjectNode(
            node_id=planned.node_id, name=planned.name, device=planned.device, baud_kbit=planned.baud_kbit,
            mandatory=planned.node_id not in optional, channels=planned.channels, pdo_ids=planned.pdo_ids,
            identity=expected_identity(profile) if profile else ExpectedIdentity(),
            profile=profile_ref(registry, profile.id) if profile else None, parameter_set=parameter_set, pdo=pdo))
    return LineProject(name=plan.name, cable=plan.cable, nodes=nodes).sorted()


def _profile_notes(project: LineProject, registry: ProfileRegistry) -> list[str]:
    notes: list[str] = []
    for node in project.nodes:
        ref = node.profile
        if ref is None:
            continue
        try:
            registry.get(ref.id)
        except DriveBenchError:
            if ref.embedded is None:
                notes.append(_("Node {node}: profile '{id}' is missing on this server and not in the file; upload "
                               "it (Profiles page), then open the project again for its parameter set.").format(
                                   node=node.node_id, id=ref.id))
                continue
            registry.add_upload(ref.embedded.filename, ref.embedded.content.encode())
            notes.append(_("Node {node}: loaded the profile '{id}' the file carries.").format(node=node.node_id,
                                                                                            id=ref.id))
            continue
        if ref.sha256 and profile_ref(registry, ref.id).sha256 != ref.sha256:
            notes.append(_("Node {node}: profile '{id}' on this server differs from the project's (another "
                           "version or edited).").format(node=node.node_id, id=ref.id))
    return notes


def _checked_sets(project: LineProject, registry: ProfileRegistry) -> dict[int, tuple[Profile, Values]]:
    """Each node's set values checked as a set import checks them (known parameter, writable, type, range), before
    anything is stored; nodes whose profile is not on this server are left out (named by the notes)."""
    checked: dict[int, tuple[Profile, Values]] = {}
    for node in project.nodes:
        values = node.set_values()
        if node.profile is None or not values:
            continue
        try:
            profile = registry.get(node.profile.id)
        except DriveBenchError:
            continue
        catalog = catalog_for(profile)
        given: dict[str, object] = {}
        for ref, raw in values.items():
            try:
                given[ref] = engineering(catalog.resolve(ref), raw)
            except DriveBenchError:
                given[ref] = raw  # named by the check below
        source = _("node {node} of the project").format(node=node.node_id)
        checked[node.node_id] = profile, set_formats.checked_values(profile, given, source)
    return checked


def open_project(project: LineProject, registry: ProfileRegistry, *, user: str, url: str | None = None
                 ) -> OpenedProject:
    """Recreate a project on this server: profiles, planned network, parameter sets, the project itself. A value
    that does not fit its profile refuses the whole project before anything is stored."""
    notes = _profile_notes(project, registry)
    checked = _checked_sets(project, registry)
    network = PlannedNetworkStore(url).save(project.plan())
    sets = ParameterSetStore(url)
    nodes = []
    for node in project.nodes:
        if node.node_id not in checked:
            nodes.append(node)
            continue
        profile, values = checked[node.node_id]
        name = node.parameter_set.name if node.parameter_set else f"{project.name} node {node.node_id}"
        stored = sets.create(name, profile, values, user=user, note=_("from line project '{name}'").format(
            name=project.name), reason="line project")
        kept = node.parameter_set or ProjectSet(name=name)
        nodes.append(node.model_copy(update={"parameter_set": kept.model_copy(update={"set_id": stored.info.id})}))
    saved = LineProjectStore(url).save(project.model_copy(update={"nodes": nodes}), network.id)
    return OpenedProject(**saved.model_dump(), notes=notes)
