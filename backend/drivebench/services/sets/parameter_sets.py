"""Parameter sets: a node's parameter values stored under a name, with history, compared and copied.

A set belongs to one device profile (id + version). Its values are raw values by canonical ref
(``{"C00088": 1020, "0x1017": 500}``) in the profile's order, stored as one JSON body per version, so a
5,000-parameter set is one row to load and one dict to compare. Every change of the values is a new version; the
old ones stay (history). Only parameters a download can write go into a set: readable and writable, and not
device commands (``C00002/x``, ``0x1010``/``0x1011`` save/restore, reset node) - downloading those would
*do* something rather than set something.

Jobs that talk to the device (upload, download, retry, rollback) are in ``services/sets/set_jobs.py``; file formats
in ``services/sets/set_formats.py``.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from pydantic import BaseModel, ConfigDict
from sqlalchemy import delete, select, update

from drivebench.device.formats.eds import resolve_node_expr
from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.factory_default import same_raw
from drivebench.device.profiles.profile import ObjectEntry, Profile
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import Conflict, InvalidValue, NotFound
from drivebench.i18n import N_, _
from drivebench.services.params import reads
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import DownloadRow, ParameterSetRow, ParameterSetVersionRow, utcnow
from drivebench.services.storage.server_process import SERVER

Raw = int | float | str
Values = dict[str, Raw]

COMMAND_INDICES = (0x1010, 0x1011)
_COMMAND_NAME = re.compile(r"device command|reset node|save all|restore", re.IGNORECASE)
_NODE_ADDRESS_NAME = re.compile(r"(node address|device address|node id)$", re.IGNORECASE)
_COB_BASES = (0x080, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580, 0x600, 0x700)


# --- what a set holds ---------------------------------------------------------------------------------------
def is_command(item: Item) -> bool:
    return (item.index in COMMAND_INDICES or item.group == "Device commands"
            or bool(_COMMAND_NAME.search(item.name)))


TOOL_CHANNELS = range(0x1201, 0x1280)
"""Additional SDO server parameters: DriveBench activates SDO2 itself to read faster (not saved on the device), so
an upload would store the tool's own state; a set leaves them out."""


def settable(item: Item) -> bool:
    """Whether a set stores this item: readable, writable, not a device command, not an SDO channel the tool
    opens for itself, not what the profile marks as process data or volatile (``Entry.live``)."""
    access = item.entry.access
    return (access.readable and access.writable and not is_command(item) and item.index not in TOOL_CHANNELS
            and item.entry.live is None)


def every_item(profile: Profile) -> list[Item]:
    """The profile's items and the codes of its parameter sets 2 and up (C2012 ...), in that order."""
    catalog = catalog_for(profile)
    return [*catalog.items, *catalog.set_items]


def settable_items(profile: Profile) -> list[Item]:
    """What a set of this profile holds: every parameter set's settable items."""
    return [item for item in every_item(profile) if settable(item)]


def live_items(profile: Profile) -> list[Item]:
    """Writable items a set leaves out because the profile marks them as process data or volatile."""
    return [item for item in every_item(profile) if item.entry.live is not None and item.entry.access.writable]


RPDO_MAPPINGS = range(0x1600, 0x1800)


def rpdo_mapped(values: Mapping[str, Raw]) -> set[tuple[int, int]]:
    """(index, sub-index) of the objects the RPDO mapping values (0x1600..0x17FF, CiA 301) among ``values``
    map: process data the master sends, not settings."""
    mapped: set[tuple[int, int]] = set()
    for ref, raw in values.items():
        match = re.fullmatch(r"0x(1[67][0-9A-F]{2})\.(\d+)", ref)
        if match is None or not isinstance(raw, int) or raw == 0:
            continue
        count = values.get(f"0x{match.group(1)}")
        if isinstance(count, int) and int(match.group(2)) > count:
            continue  # an entry beyond the number of mapped objects maps nothing
        mapped.add((raw >> 16, (raw >> 8) & 0xFF))
    return mapped


def engineering(item: Item, raw: Raw) -> object:
    """A raw value as :func:`writes.write` takes it (engineering units; hex text for byte strings)."""
    if isinstance(raw, str):
        return raw
    factor = item.entry.factor
    return raw / factor if factor != 1 else raw


def shown(item: Item, raw: Raw | None) -> str | None:
    """``10.20 A``, ``0 = 500 kbit/s`` ... (what the Parameters tab shows)."""
    if raw is None:
        return None
    return reads.display(item, from_raw(item.entry, raw))


def default_raw(item: Item, node_id: int | None) -> Raw | None:
    """The profile's default as a raw value (``$NODEID`` formulas for ``node_id``), None where there is none."""
    entry = item.entry
    if isinstance(entry, ObjectEntry) and entry.default_expr is not None:
        return resolve_node_expr(entry.default_expr, node_id) if node_id is not None else None
    default = entry.default
    if default is None or isinstance(default, str):
        return default
    if entry.data_type.is_float:
        return float(default) * float(entry.factor)
    return round(default * entry.factor)


def defaults_of(profile: Profile, node_id: int | None = None) -> Values:
    found: Values = {}
    for item in settable_items(profile):
        raw = default_raw(item, node_id)
        if raw is not None:
            found[item.ref] = raw
    return found


# --- stored sets -------------------------------------------------------------------------------------------
class SetInfo(BaseModel):
    """A stored set without its values (also the API's answer)."""

    model_config = ConfigDict(frozen=True)

    id: int
    name: str
    profile_id: str
    profile_version: str
    device: str
    node_id: int | None
    session_id: str | None
    created: datetime
    updated: datetime
    created_by: str
    note: str
    version: int
    count: int


@dataclass(frozen=True)
class StoredSet:
    info: SetInfo
    values: Values
    """Raw values by ref, of the version asked for (the newest by default)."""
    version: int


class SetVersion(BaseModel):
    model_config = ConfigDict(frozen=True)

    version: int
    created: datetime
    created_by: str
    reason: str
    count: int


def _info(row: ParameterSetRow, count: int) -> SetInfo:
    return SetInfo(id=row.id, name=row.name, profile_id=row.profile_id, profile_version=row.profile_version,
                   device=row.device, node_id=row.node_id, session_id=row.session_id, created=row.created,
                   updated=row.updated, created_by=row.created_by, note=row.note, version=row.version, count=count)


def _check_name(name: str) -> str:
    cleaned = " ".join(name.split())
    if not cleaned or len(cleaned) > 200:
        raise InvalidValue(_("A parameter set needs a name of 1 to 200 characters"))
    return cleaned


class ParameterSetStore:
    """Sets in the database at ``url`` (None: ``settings.database_url``, read at each call)."""

    def __init__(self, url: str | None = None) -> None:
        self.url = url

    def create(self, name: str, profile: Profile, values: Mapping[str, Raw], *, user: str,
               node_id: int | None = None, session_id: str | None = None, note: str = "",
               reason: str = "created") -> StoredSet:
        """Store a new set (version 1) in one transaction."""
        now = utcnow()
        body = dict(values)
        with transaction(self.url) as db:
            row = ParameterSetRow(name=_check_name(name), profile_id=profile.id, profile_version=profile.version,
                                  device=profile.identity.product_name, node_id=node_id, session_id=session_id,
                                  created=now, updated=now, created_by=user, note=note, version=1)
            db.add(row)
            db.flush()
            db.add(ParameterSetVersionRow(set_id=row.id, version=1, created=now, created_by=user, reason=reason,
                                          count=len(body), body={"values": body}))
            return StoredSet(_info(row, len(body)), body, 1)

    def all(self, profile_id: str | None = None) -> list[SetInfo]:
        """Newest first, with the number of values of each set's current version."""
        count = (select(ParameterSetVersionRow.count)
                 .where(ParameterSetVersionRow.set_id == ParameterSetRow.id,
                        ParameterSetVersionRow.version == ParameterSetRow.version)
                 .scalar_subquery())
        statement = select(ParameterSetRow, count).order_by(ParameterSetRow.updated.desc(), ParameterSetRow.id.desc())
        if profile_id:
            statement = statement.where(ParameterSetRow.profile_id == profile_id)
        with transaction(self.url) as db:
            return [_info(row, number or 0) for row, number in db.execute(statement)]

    def _row(self, db: Any, set_id: int) -> ParameterSetRow:
        row: ParameterSetRow | None = db.get(ParameterSetRow, set_id)
        if row is None:
            raise NotFound(_("No parameter set {id}").format(id=set_id))
        return row

    def get(self, set_id: int, version: int | None = None) -> StoredSet:
        with transaction(self.url) as db:
            row = self._row(db, set_id)
            wanted = version or row.version
            body = db.scalars(select(ParameterSetVersionRow).where(ParameterSetVersionRow.set_id == set_id,
                                                                   ParameterSetVersionRow.version == wanted)).first()
            if body is None:
                raise NotFound(_("Parameter set {id} has no version {version}").format(id=set_id, version=wanted))
            values: Values = dict(body.body.get("values", {}))
            return StoredSet(_info(row, body.count), values, wanted)

    def _row_to_edit(self, db: Any, set_id: int, base_version: int | None) -> ParameterSetRow:
        """The set's row, locked until the edit commits (PostgreSQL: a second server's edit waits, then sees the new
        version); Conflict, naming who made the newer version and when, if ``base_version`` is not the current."""
        row: ParameterSetRow | None = db.scalar(select(ParameterSetRow).where(ParameterSetRow.id == set_id)
                                                .with_for_update())
        if row is None:
            raise NotFound(_("No parameter set {id}").format(id=set_id))
        if base_version is not None and base_version != row.version:
            newest = db.scalar(select(ParameterSetVersionRow).where(ParameterSetVersionRow.set_id == set_id,
                                                                    ParameterSetVersionRow.version == row.version))
            who, when = (newest.created_by, newest.created) if newest else (row.created_by, row.updated)
            when = when if when.tzinfo else when.replace(tzinfo=UTC)
            raise Conflict(_("Parameter set {id} '{name}' was changed by {who} at {moment} UTC: it is now version "
                             "{version}, and your change was made to version {base}. Nothing was saved.").format(
                id=set_id, name=row.name, who=who, moment=f"{when.astimezone(UTC):%Y-%m-%d %H:%M:%S}",
                version=row.version, base=base_version),
                           hint=N_("Reload the set, look at the newer values and make your change again."))
        return row

    def rename(self, set_id: int, name: str | None = None, note: str | None = None, *,
               base_version: int | None = None) -> SetInfo:
        """New name and note (not a new version: the values stay); refused when the values have moved on past
        ``base_version``."""
        with transaction(self.url) as db:
            row = self._row_to_edit(db, set_id, base_version)
            if name is not None:
                row.name = _check_name(name)
            if note is not None:
                row.note = note
            row.updated = utcnow()
        return self.get(set_id).info

    def update_values(self, set_id: int, values: Mapping[str, Raw], *, user: str, reason: str,
                      base_version: int | None = None) -> StoredSet:
        """A new version with these values (the old versions stay). With ``base_version`` (the version the values
        were edited from) a set changed meanwhile, by this server or another of the database, is a Conflict."""
        body = dict(values)
        with transaction(self.url) as db:
            row = self._row_to_edit(db, set_id, base_version)
            row.version += 1
            row.updated = utcnow()
            db.add(ParameterSetVersionRow(set_id=set_id, version=row.version, created=row.updated, created_by=user,
                                          reason=reason, count=len(body), body={"values": body}))
            db.flush()
            return StoredSet(_info(row, len(body)), body, row.version)

    def delete(self, set_id: int) -> None:
        with transaction(self.url) as db:
            self._row(db, set_id)
            # bulk statements: the versions go first (SQLite without the foreign-key pragma does not cascade),
            # downloads keep their report with set_id NULL (ON DELETE SET NULL)
            db.execute(delete(ParameterSetVersionRow).where(ParameterSetVersionRow.set_id == set_id))
            db.execute(update(DownloadRow).where(DownloadRow.set_id == set_id).values(set_id=None))
            db.execute(delete(ParameterSetRow).where(ParameterSetRow.id == set_id))

    def history(self, set_id: int) -> list[SetVersion]:
        """Newest first."""
        with transaction(self.url) as db:
            self._row(db, set_id)
            rows = db.scalars(select(ParameterSetVersionRow).where(ParameterSetVersionRow.set_id == set_id)
                              .order_by(ParameterSetVersionRow.version.desc()))
            return [SetVersion(version=r.version, created=r.created, created_by=r.created_by, reason=r.reason,
                               count=r.count) for r in rows]

    # --- downloads ---------------------------------------------------------------------------------------
    def start_download(self, *, kind: str, session_id: str, node_id: int, profile_id: str, user: str,
                       before: Mapping[str, Raw], set_id: int | None = None,
                       set_version: int | None = None) -> int:
        """Record a download with the values read first; committed before the first write is sent."""
        with transaction(self.url) as db:
            row = DownloadRow(kind=kind, set_id=set_id, set_version=set_version, session_id=session_id,
                              node_id=node_id, profile_id=profile_id, user=user, started=utcnow(), state="running",
                              before=dict(before), report=[], server=SERVER)
            db.add(row)
            db.flush()
            return row.id

    def finish_download(self, download_id: int, state: str, report: list[dict[str, Any]]) -> None:
        with transaction(self.url) as db:
            row = db.get(DownloadRow, download_id)
            if row is None:
                raise NotFound(_("No download {id}").format(id=download_id))
            row.state, row.report, row.finished = state, report, utcnow()

    def download(self, download_id: int) -> DownloadRow:
        with transaction(self.url) as db:
            row = db.get(DownloadRow, download_id)
            if row is None:
                raise NotFound(_("No download {id}").format(id=download_id))
            db.expunge(row)
            return row

    def interrupt_downloads(self, gone: Callable[[str], bool]) -> list[int]:
        """Store as ``interrupted`` the downloads still ``running`` whose server process is ``gone``."""
        with transaction(self.url) as db:
            running = db.execute(select(DownloadRow.id, DownloadRow.server).where(DownloadRow.state == "running"))
            ids = [download_id for download_id, server in running if server is not None and gone(server)]
            if ids:
                db.execute(update(DownloadRow).where(DownloadRow.id.in_(ids), DownloadRow.state == "running")
                           .values(state="interrupted"))
            return ids

    def downloads(self, *, node_id: int | None = None, limit: int = 50) -> list[DownloadRow]:
        statement = select(DownloadRow).order_by(DownloadRow.id.desc()).limit(limit)
        if node_id is not None:
            statement = statement.where(DownloadRow.node_id == node_id)
        with transaction(self.url) as db:
            rows = list(db.scalars(statement))
            for row in rows:
                db.expunge(row)
            return rows


# --- copy to another node -----------------------------------------------------------------------------------
def retarget(profile: Profile, values: Mapping[str, Raw], from_node: int, to_node: int) -> tuple[Values, list[str]]:
    """The values for an identical drive at ``to_node``: its own node address, and the COB-IDs the predefined
    connection set derives from the node id (CiA 301 ``$NODEID`` formulas, ``0x180 + node`` ...) moved along.
    Returns the values and one note per changed parameter."""
    catalog = catalog_for(profile)
    moved: Values = {}
    notes: list[str] = []
    for ref, raw in values.items():
        new = raw
        item = _item(catalog, ref)
        if item is not None and isinstance(raw, int) and not isinstance(raw, bool):
            entry = item.entry
            if raw == from_node and _NODE_ADDRESS_NAME.search(entry.name):
                new = to_node
            elif isinstance(entry, ObjectEntry) and entry.default_expr and "NODEID" in entry.default_expr.upper():
                if raw & 0x7F == from_node and (raw & 0x780) in _COB_BASES:
                    new = raw - from_node + to_node
            elif re.search(r"cob-?id|identifier", item.name, re.IGNORECASE) and raw & 0x7F == from_node \
                    and raw & 0x780 in _COB_BASES and raw < 0x800:
                new = raw - from_node + to_node
        if new != raw and item is not None:
            notes.append(f"{ref} ({item.name}): {shown(item, raw)} -> {shown(item, new)}")
        moved[ref] = new
    return moved, notes


def _item(catalog: Catalog, ref: str) -> Item | None:
    try:
        return catalog.resolve(ref)
    except Exception:  # a ref the profile no longer knows: compare and download report it
        return None


# --- compare ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Source:
    """One side of a comparison: raw values by ref for one profile."""

    label: str
    profile: Profile
    values: Values
    unread: dict[str, str] = field(default_factory=dict)
    """Refs that could not be read from a device, with why."""


class Difference(BaseModel):
    model_config = ConfigDict(frozen=True)

    ref: str
    name: str
    group: str
    unit: str | None
    left: str | None
    right: str | None
    left_raw: Raw | None
    right_raw: Raw | None
    kind: str
    """``changed``, ``only left``, ``only right`` or ``unreadable``."""


class Comparison(BaseModel):
    model_config = ConfigDict(frozen=True)

    left: str
    right: str
    profile_id: str
    compared: int
    equal: int
    rows: list[Difference]
    """Differences only, in the profile's order, after the filter."""
    total_differences: int


def compare(left: Source, right: Source, *, query: str = "", group: str | None = None) -> Comparison:
    """The parameters in which the two sources differ (a ref only one side has counts as a difference)."""
    if left.profile.id != right.profile.id:
        raise Conflict(_("'{left}' is a {left_device} and '{right}' a {right_device}: only sets of one device type "
                         "compare").format(left=left.label, left_device=left.profile.identity.product_name,
                                           right=right.label, right_device=right.profile.identity.product_name))
    catalog = catalog_for(left.profile)
    words = query.lower().split()
    rows: list[Difference] = []
    refs = list(left.values) + [ref for ref in right.values if ref not in left.values]
    refs += [ref for ref in (*left.unread, *right.unread) if ref not in left.values and ref not in right.values]
    equal = 0
    total = 0
    for ref in refs:
        a, b = left.values.get(ref), right.values.get(ref)
        if a is not None and b is not None and same_raw(a, b):
            equal += 1
            continue
        total += 1
        item = _item(catalog, ref)
        name = item.name if item else _("(not in the profile)")
        item_group = item.group if item else ""
        if words and not all(w in f"{ref} {name}".lower() for w in words):
            continue
        if group and item_group != group:
            continue
        if ref in left.unread or ref in right.unread:
            kind = "unreadable"
        elif a is None:
            kind = "only right"
        elif b is None:
            kind = "only left"
        else:
            kind = "changed"
        left_text = shown(item, a) if item else (None if a is None else str(a))
        right_text = shown(item, b) if item else (None if b is None else str(b))
        if ref in left.unread:
            left_text = left.unread[ref]
        if ref in right.unread:
            right_text = right.unread[ref]
        rows.append(Difference(ref=ref, name=name, group=item_group, unit=item.entry.unit if item else None,
                               left=left_text, right=right_text, left_raw=a, right_raw=b, kind=kind))
    return Comparison(left=left.label, right=right.label, profile_id=left.profile.id, compared=len(refs),
                      equal=equal, rows=rows, total_differences=total)


def comparison_csv(comparison: Comparison) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["code", "name", "unit", comparison.left, comparison.right, "left raw", "right raw", "kind"])
    for row in comparison.rows:
        writer.writerow([row.ref, row.name, row.unit or "", row.left or "", row.right or "",
                         "" if row.left_raw is None else row.left_raw,
                         "" if row.right_raw is None else row.right_raw, row.kind])
    return out.getvalue()


def set_source(stored: StoredSet, profile: Profile) -> Source:
    label = _("Set '{name}' v{version}").format(name=stored.info.name, version=stored.version)
    return Source(label, profile, stored.values)


def defaults_source(profile: Profile, node_id: int | None = None) -> Source:
    return Source(_("{device} defaults").format(device=profile.identity.product_name), profile,
                  defaults_of(profile, node_id))


def ordered(profile: Profile, refs: Iterable[str]) -> list[str]:
    """Refs in the profile's order (unknown ones last, as given)."""
    wanted = set(refs)
    known = [item.ref for item in every_item(profile) if item.ref in wanted]
    rest = [ref for ref in refs if ref not in set(known)]
    return known + rest
