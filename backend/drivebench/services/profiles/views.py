"""What the API and the Profiles page show of a profile: summary, import warnings, load errors, searched entries."""

from __future__ import annotations

import re
from typing import Literal

from pydantic import BaseModel

from drivebench.device.formats.eds import ImportWarning
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.loader import LoadedFile, ProfileRegistry
from drivebench.device.profiles.profile import ObjectEntry, Parameter, Profile, Value
from drivebench.errors import ProfileError
from drivebench.i18n import shown

EntryKind = Literal["all", "parameters", "objects"]


class ProfileSummary(BaseModel):
    id: str
    version: str
    family: str
    vendor: str
    product: str
    vendor_id: int | None
    product_code: int | None
    transport: str
    objects: int
    parameters: int
    builtin: bool
    source: str | None = None
    uploaded_as: str | None = None
    """The file name an uploaded profile came in as (shown only; it is stored as ``<id>.<suffix>``)."""
    warning_count: int = 0
    """How many quirks of the file the import read with a warning (``/api/profiles/{id}/warnings``)."""


class ImportWarningOut(BaseModel):
    """A quirk of a device description and the reading the import applied."""

    file: str
    line: int | None
    key: str | None
    message: str
    object: str | None
    """``0x6040sub0`` when the warning concerns one object."""
    limits: bool
    """The object's limits were repaired or dropped (a write of it says so first)."""


class UploadResult(ProfileSummary):
    warnings: list[ImportWarningOut]


class LoadError(BaseModel):
    """A profile file that did not load: which file, where in it, and why."""

    file: str
    line: int | None
    reason: str


class EntryRow(BaseModel):
    """One row of a profile's table: a vendor parameter (code/subcode) or a CANopen object (index/subindex)."""

    ref: str
    kind: Literal["parameter", "object"]
    code: str | None
    """The vendor code; for an object, the code that shows the same data (cross reference), if any."""
    subcode: int | None
    name: str
    index: str
    subindex: int
    parameter_set: int
    data_type: str
    access: str
    unit: str | None
    factor: int | float
    default: Value | None
    min: int | float | None
    max: int | float | None
    selection: dict[int, str]
    bits: dict[int, str]
    reset_required: bool
    pdo_mappable: bool
    group: str
    description: str | None
    limits_note: str | None = None
    """The file's LowLimit/HighLimit of this object were repaired or dropped on import: how."""


class EntryPage(BaseModel):
    profile: str
    q: str
    kind: EntryKind
    total: int
    offset: int
    limit: int
    items: list[EntryRow]


def summary(profile: Profile, registry: ProfileRegistry) -> ProfileSummary:
    return ProfileSummary(id=profile.id, version=profile.version, family=profile.family,
                          vendor=profile.identity.vendor_name, product=profile.identity.product_name,
                          vendor_id=profile.identity.vendor_id, product_code=profile.identity.product_code,
                          transport=profile.features.transport, objects=len(profile.objects),
                          parameters=len(profile.parameters), builtin=registry.is_builtin(profile.id),
                          source=profile.source, uploaded_as=registry.uploaded_as(profile.id),
                          warning_count=len(registry.loaded(profile.id).warnings))


def warning_out(warning: ImportWarning) -> ImportWarningOut:
    where = f"0x{warning.index:04X}sub{warning.subindex}" if warning.index is not None else None
    return ImportWarningOut(file=warning.file, line=warning.line, key=warning.key, message=shown(warning.message),
                            object=where, limits=warning.limits)


def upload_result(profile: Profile, registry: ProfileRegistry) -> UploadResult:
    warnings = [warning_out(w) for w in registry.loaded(profile.id).warnings]
    return UploadResult(**summary(profile, registry).model_dump(), warnings=warnings)


def split_location(file: str, message: str) -> LoadError:
    """``"x.eds:12: reason"`` (as ProfileError words it) -> file, line 12, reason."""
    rest = message[len(file) + 1:].lstrip() if message.startswith(file + ":") else message
    found = re.match(r"^(\d+):\s*(.*)$", rest, re.DOTALL)
    if found:
        return LoadError(file=file, line=int(found.group(1)), reason=found.group(2))
    return LoadError(file=file, line=None, reason=rest)


def load_errors(registry: ProfileRegistry) -> list[LoadError]:
    return [split_location(file, shown(message)) for file, message in registry.errors]


def upload_error(exc: ProfileError) -> LoadError:
    """Where an upload failed; ``file`` is empty when the upload was refused before its name was read."""
    detail = exc.shown_detail()
    return split_location(exc.source, detail) if exc.source else LoadError(file="", line=None, reason=detail)


def entry_row(item: Item, loaded: LoadedFile | None = None) -> EntryRow:
    entry = item.entry
    is_parameter = isinstance(entry, Parameter)
    return EntryRow(
        ref=item.ref, kind="parameter" if is_parameter else "object",
        code=entry.code if isinstance(entry, Parameter | ObjectEntry) else None,
        subcode=entry.subcode if isinstance(entry, Parameter) else None,
        name=item.name, index=f"0x{item.index:04X}", subindex=item.subindex, parameter_set=item.parameter_set,
        data_type=entry.data_type.value, access=entry.access.value, unit=entry.unit, factor=entry.factor,
        default=entry.default, min=entry.min, max=entry.max, selection=entry.selection, bits=entry.bits,
        reset_required=entry.reset_required, pdo_mappable=entry.pdo_mappable, group=item.group,
        description=entry.description,
        limits_note=loaded.limits_note(item.index, item.subindex) if loaded and loaded.warnings else None)


def find_entries(profile: Profile, q: str, kind: EntryKind) -> list[Item]:
    """Entries matching ``q`` (code ``C00088``/``88``, name words, index ``0x5FA7``), exact match first."""
    items = catalog_for(profile).search(q)
    if kind == "parameters":
        return [i for i in items if isinstance(i.entry, Parameter)]
    if kind == "objects":
        return [i for i in items if not isinstance(i.entry, Parameter)]
    return items


def entry_page(profile: Profile, q: str, kind: EntryKind, offset: int, limit: int,
               loaded: LoadedFile | None = None) -> EntryPage:
    items = find_entries(profile, q, kind)
    rows = [entry_row(i, loaded) for i in items[offset:offset + limit]]
    return EntryPage(profile=profile.id, q=q, kind=kind, total=len(items), offset=offset, limit=limit, items=rows)
