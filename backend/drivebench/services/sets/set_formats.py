"""Parameter sets as files: JSON (our schema), CSV (code, name, value, unit) and CiA 306 DCF; export and import.

An import checks every value against the target profile (known parameter, writable, type width, range,
selection list) and reports *all* values that do not fit, each with its line, before anything is stored.

JSON schema (``ParameterSetFile``, published at ``/api/parameter-sets/schema``)::

    {"schema": "drivebench.parameter-set/1", "name": "Conveyor 1", "profile_id": "lenze-8400-motec-canopen",
     "profile_version": "1", "device": "8400 motec", "node_id": 5, "created": "...", "created_by": "anna",
     "note": "", "parameters": [
       {"ref": "C00088", "name": "Rated motor current", "value": 10.2, "unit": "A", "raw": 1020},
       ...]}

``value`` (engineering units, what the manual prints) is what an import reads; ``raw`` is used only where
``value`` is missing. Each parameter is written on its own line, so an error names a line a person can find.
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from drivebench.device.formats.eds import decode_text, parse_ini, parse_value, resolve_node_expr
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.xdc_rewrite import rewrite_xdc
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.profile import Profile
from drivebench.device.profiles.scaling import format_value, to_raw
from drivebench.errors import DriveBenchError, InvalidValue, ProfileError, UnknownParameter
from drivebench.i18n import N_, _, ngettext, shown
from drivebench.services.sets.parameter_sets import (
    TOOL_CHANNELS,
    Raw,
    StoredSet,
    Values,
    catalog_for,
    engineering,
    is_command,
    ordered,
    settable,
)

SCHEMA_ID = "drivebench.parameter-set/1"
MAX_SET_FILE_BYTES = 8 * 1024 * 1024
FORMATS = ("json", "csv", "dcf")
ProfileLookup = Callable[[str], Profile]


class FileParameter(BaseModel):
    model_config = ConfigDict(extra="ignore")

    ref: str = Field(description="Vendor code or index: C00088, C00118/3, P2040, 0x1017")
    name: str | None = None
    value: int | float | str | None = Field(None, description="Engineering units (10.2 for 10.20 A)")
    unit: str | None = None
    raw: int | float | str | None = Field(None, description="Raw device value; used only without 'value'")


class ParameterSetFile(BaseModel):
    """A parameter set file: the profile it is for (id and version) and its values."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True)

    schema_id: Literal["drivebench.parameter-set/1"] = Field("drivebench.parameter-set/1", alias="schema")
    name: str = Field(min_length=1, max_length=200)
    profile_id: str
    profile_version: str = "1"
    device: str | None = None
    node_id: int | None = Field(None, ge=1, le=127)
    created: datetime | None = None
    created_by: str | None = None
    note: str = ""
    parameters: list[FileParameter]


@dataclass(frozen=True)
class LineError:
    line: int | None
    ref: str | None
    detail: str

    def __str__(self) -> str:
        where = _("line {line}: ").format(line=self.line) if self.line else ""
        return f"{where}{self.ref + ': ' if self.ref else ''}{self.detail}"


class SetImportError(InvalidValue):
    """A file that does not fit the target profile; ``errors`` name every line that does not."""

    title = N_("Parameter set file does not fit")

    def __init__(self, source: str, errors: list[LineError]) -> None:
        shown = "; ".join(str(e) for e in errors[:5])
        if len(errors) > 5:
            shown += "; " + _("... {count} more").format(count=len(errors) - 5)
        super().__init__(ngettext("{source}: {count} value does not fit: {errors}",
                                  "{source}: {count} values do not fit: {errors}", len(errors)).format(
            source=source, count=len(errors), errors=shown))
        self.source = source
        self.errors = errors

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "source": self.source,
                "errors": [{"line": e.line, "ref": e.ref, "detail": e.detail} for e in self.errors]}


@dataclass
class ImportedSet:
    name: str
    profile: Profile
    values: Values
    note: str = ""
    node_id: int | None = None
    notes: list[str] = field(default_factory=list)


# --- values --------------------------------------------------------------------------------------------------
def _raw_for(item: Item, value: object) -> Raw:
    """A value from a file -> raw, checked like a write (raises a ParameterError)."""
    if is_command(item):
        raise InvalidValue(_("is a device command, not a setting; sets do not hold it"))
    if not item.entry.access.readable:
        raise InvalidValue(_("is write-only; a set holds values that can be read back"))
    if item.index in TOOL_CHANNELS:
        raise InvalidValue(_("is an additional SDO channel (DriveBench opens SDO2 itself); sets do not hold it"))
    raw = to_raw(item.entry, value, ref=item.ref)
    return raw.hex() if isinstance(raw, bytes) else raw


def _check(catalog: Catalog, ref: str, value: object, line: int | None, values: Values,
           errors: list[LineError]) -> None:
    try:
        item = catalog.resolve(ref)
        if item.ref in values:
            raise InvalidValue(_("appears twice (as {ref})").format(ref=item.ref))
        values[item.ref] = _raw_for(item, value)
    except DriveBenchError as exc:
        errors.append(LineError(line, ref, _without_label(exc.shown_detail(), ref)))


def checked_values(profile: Profile, values: Mapping[str, object], source: str) -> Values:
    """Values by ref (engineering values, as a file gives them) checked like an import: raw values in the profile's
    refs, or a ``SetImportError`` naming every one that does not fit."""
    catalog = catalog_for(profile)
    checked: Values = {}
    errors: list[LineError] = []
    for ref, value in values.items():
        _check(catalog, ref, value, None, checked, errors)
    if errors:
        raise SetImportError(source, errors)
    return checked


def _without_label(detail: str, ref: str) -> str:
    return detail[len(ref):].lstrip(" :") if detail.startswith(ref) else detail


def text_value(item: Item, raw: Raw) -> str:
    """A raw value as a person types it (CSV): ``10.20``, ``0``, ``hello``."""
    if isinstance(raw, str):
        return raw
    entry = item.entry
    value = raw / entry.factor if entry.factor != 1 else raw
    if isinstance(value, float) and entry.factor == 1:
        return repr(value)
    return format_value(entry, value)


def _source_name(source: str | None, default: str) -> str:
    return source or default


# --- JSON ----------------------------------------------------------------------------------------------------
def to_file(stored: StoredSet, profile: Profile) -> ParameterSetFile:
    catalog = catalog_for(profile)
    parameters: list[FileParameter] = []
    for ref, raw in stored.values.items():
        item = catalog.resolve(ref)
        value = engineering(item, raw)
        parameters.append(FileParameter(ref=ref, name=item.name, value=value if isinstance(value, (int, float, str))
                                        else raw, unit=item.entry.unit, raw=raw))
    info = stored.info
    return ParameterSetFile(name=info.name, profile_id=info.profile_id, profile_version=info.profile_version,
                            device=info.device, node_id=info.node_id, created=info.created,
                            created_by=info.created_by, note=info.note, parameters=parameters)


def export_json(stored: StoredSet, profile: Profile) -> str:
    document = to_file(stored, profile)
    head = document.model_dump(mode="json", by_alias=True, exclude={"parameters"})
    lines = [json.dumps(p.model_dump(mode="json"), ensure_ascii=False) for p in document.parameters]
    body = json.dumps(head, ensure_ascii=False, indent=1)[:-2]  # without the closing "\n}"
    return body + ',\n "parameters": [\n  ' + ",\n  ".join(lines) + "\n ]\n}\n"


def import_json(text: str, profiles: ProfileLookup, *, source: str | None = None) -> ImportedSet:
    name = _source_name(source, _("JSON file"))
    try:
        document = ParameterSetFile.model_validate_json(text)
    except ValidationError as exc:
        problems = [LineError(None, None, f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}")
                    for e in exc.errors()]
        raise SetImportError(name, problems) from exc
    profile = profiles(document.profile_id)
    catalog = catalog_for(profile)
    ref_lines = [n for n, line in enumerate(text.splitlines(), start=1) if re.search(r'"ref"\s*:', line)]
    values: Values = {}
    errors: list[LineError] = []
    for position, parameter in enumerate(document.parameters):
        line = ref_lines[position] if position < len(ref_lines) else None
        value: object = parameter.value
        if value is None and parameter.raw is not None:
            try:
                value = engineering(catalog.resolve(parameter.ref), parameter.raw)
            except UnknownParameter as exc:
                errors.append(LineError(line, parameter.ref, exc.shown_detail()))
                continue
        if value is None:
            errors.append(LineError(line, parameter.ref, _("has neither 'value' nor 'raw'")))
            continue
        _check(catalog, parameter.ref, value, line, values, errors)
    if errors:
        raise SetImportError(name, errors)
    notes = _version_note(document.profile_version, profile)
    return ImportedSet(document.name, profile, values, document.note, document.node_id, notes)


def _version_note(version: str | None, profile: Profile) -> list[str]:
    if version and version != profile.version:
        return [_("The file was made for version {version} of profile '{profile}'; version {installed} is installed "
                  "(every value was checked against it)").format(version=version, profile=profile.id,
                                                                 installed=profile.version)]
    return []


# --- CSV -----------------------------------------------------------------------------------------------------
CSV_HEADER = ["code", "name", "value", "unit"]
_CSV_META = re.compile(r"^#\s*DriveBench parameter set:(?P<meta>.*)$", re.IGNORECASE)


def export_csv(stored: StoredSet, profile: Profile) -> str:
    catalog = catalog_for(profile)
    out = io.StringIO()
    info = stored.info
    out.write(f"# DriveBench parameter set: profile={info.profile_id}; version={info.profile_version}; "
              f"name={info.name}\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_HEADER)
    for ref, raw in stored.values.items():
        item = catalog.resolve(ref)
        writer.writerow([ref, item.name, text_value(item, raw), item.entry.unit or ""])
    return out.getvalue()


def import_csv(text: str, profiles: ProfileLookup, *, profile_id: str | None = None, name: str | None = None,
               source: str | None = None) -> ImportedSet:
    """``profile_id`` (or the file's ``# DriveBench parameter set: profile=...`` line) names the target."""
    label = _source_name(source, _("CSV file"))
    lines = text.splitlines()
    meta: dict[str, str] = {}
    if lines and (match := _CSV_META.match(lines[0].strip())):
        for part in match.group("meta").split(";"):
            key, _sep, value = part.partition("=")
            meta[key.strip().lower()] = value.strip()
    target = profile_id or meta.get("profile")
    if not target:
        raise SetImportError(label, [LineError(1, None, _("no target profile: choose one, or start the file with "
                                                          "'# DriveBench parameter set: profile=<id>'"))])
    profile = profiles(target)
    catalog = catalog_for(profile)
    reader = csv.reader(io.StringIO(text))
    values: Values = {}
    errors: list[LineError] = []
    columns: dict[str, int] | None = None
    for row in reader:
        line = reader.line_num
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        if columns is None:
            lowered = [c.strip().lower() for c in row]
            if "code" not in lowered or "value" not in lowered:
                errors.append(LineError(line, None, _("expected a header line 'code,name,value,unit'")))
                break
            columns = {c: n for n, c in enumerate(lowered)}
            continue
        code = row[columns["code"]].strip() if columns["code"] < len(row) else ""
        value = row[columns["value"]] if columns["value"] < len(row) else ""
        if not code:
            errors.append(LineError(line, None, _("no code")))
            continue
        try:
            item = catalog.resolve(code)
        except UnknownParameter as exc:
            errors.append(LineError(line, code, exc.shown_detail()))
            continue
        typed: object = value if item.entry.data_type.is_string else value.strip()
        if typed == "":
            errors.append(LineError(line, code, _("no value")))
            continue
        _check(catalog, code, typed, line, values, errors)
    if columns is None and not errors:
        errors.append(LineError(None, None, _("the file has no header line 'code,name,value,unit'")))
    if errors:
        raise SetImportError(label, errors)
    set_name = name or meta.get("name") or _("Imported CSV")
    return ImportedSet(set_name, profile, values, notes=_version_note(meta.get("version"), profile))


# --- DCF -----------------------------------------------------------------------------------------------------
def _stored_items(stored: StoredSet, profile: Profile) -> list[tuple[Item, Raw]]:
    catalog = catalog_for(profile)
    return [(catalog.resolve(ref), raw) for ref, raw in stored.values.items()]


def export_dcf(stored: StoredSet, profile: Profile, node_id: int | None = None, original: bytes | None = None
               ) -> str:
    """A CiA 306 DCF of the profile with the set's values as ``ParameterValue`` (raw); with ``original`` (the
    profile's EDS/DCF file) that file with only the values changed."""
    values = {(item.index, item.subindex): raw for item, raw in _stored_items(stored, profile)}
    target = node_id or stored.info.node_id
    return export_eds(profile, node_id=target, values=values, dcf=True, original=original)


def import_dcf(data: str | bytes, profiles: ProfileLookup, *, profile_id: str | None = None,
               name: str | None = None, source: str | None = None) -> ImportedSet:
    """The ``ParameterValue`` of every writable setting in the DCF; read-only objects (and device commands) a
    DCF lists are left out (noted). The target is ``profile_id`` or the DCF's ``[DriveBench] ProfileId``."""
    label = _source_name(source, _("DCF file"))
    text = decode_text(data, label) if isinstance(data, bytes) else data
    try:
        sections = parse_ini(text, label)
    except ProfileError as exc:
        raise SetImportError(label, [LineError(exc.line, None, shown(exc.reason))]) from exc
    own = sections.get("DRIVEBENCH")
    profile_key = own.get("ProfileId") if own else None
    target = profile_id or (profile_key.value if profile_key is not None else None)
    if not target:
        raise SetImportError(label, [LineError(None, None, _("no target profile: choose one (the DCF has no "
                                                             "[DriveBench] ProfileId)"))])
    profile = profiles(target)
    catalog = catalog_for(profile)
    commissioning = sections.get("DEVICECOMISSIONING")
    node_key = commissioning.get("NodeID") if commissioning else None
    node_id: int | None = None
    if node_key is not None and node_key.value.strip():
        try:
            node_id = int(node_key.value, 0)
        except ValueError:
            node_id = None
    values: Values = {}
    errors: list[LineError] = []
    skipped = 0
    for section_name, section in sections.items():
        match = re.match(r"^([0-9A-F]{4})(?:SUB([0-9A-F]{1,2}))?$", section_name)
        key = section.get("ParameterValue")
        if match is None or key is None or not key.value.strip():
            continue
        index, sub = int(match.group(1), 16), int(match.group(2) or "0", 16)
        item = catalog.by_address(index, sub)
        if item is None:
            errors.append(LineError(key.line, f"0x{index:04X}sub{sub}", _("is not an object of this profile")))
            continue
        if not settable(item):
            skipped += 1
            continue
        try:
            text_raw = key.value
            if "$NODEID" in text_raw.upper():
                if node_id is None:
                    raise ValueError(_("{value} needs a node id ([DeviceComissioning] NodeID)").format(
                        value=repr(text_raw)))
                text_raw = str(resolve_node_expr(text_raw, node_id))
            raw = parse_value(item.entry.data_type, text_raw)
        except ValueError as exc:
            errors.append(LineError(key.line, item.ref, str(exc)))
            continue
        _check(catalog, item.ref, engineering(item, raw), key.line, values, errors)
    if errors:
        raise SetImportError(label, errors)
    notes = [ngettext("{count} read-only object or device command in the DCF was left out",
                      "{count} read-only objects or device commands in the DCF were left out", skipped).format(
        count=skipped)] if skipped else []
    version_key = own.get("Version") if own else None
    if version_key is not None:
        notes += _version_note(version_key.value, profile)
    ordered_values = {ref: values[ref] for ref in ordered(profile, values)}
    return ImportedSet(name or _("Imported DCF ({device})").format(device=profile.identity.product_name), profile,
                       ordered_values,
                       node_id=node_id, notes=notes)


def export(fmt: str, stored: StoredSet, profile: Profile, original: bytes | None = None,
           original_xml: bytes | None = None) -> tuple[str | bytes, str]:
    """(text, media type) of the set in ``fmt``; a DCF written over ``original`` (the profile's EDS/DCF file), an
    XDC over ``original_xml`` (its XDD/XDC file, then bytes in that file's encoding) where it came from one."""
    if fmt == "json":
        return export_json(stored, profile), "application/json"
    if fmt == "csv":
        return export_csv(stored, profile), "text/csv"
    if fmt == "dcf":
        return export_dcf(stored, profile, original=original), "text/plain"
    if fmt == "xdc":  # CiA 311 XML twin of the DCF (export only)
        values = {(item.index, item.subindex): raw for item, raw in _stored_items(stored, profile)}
        if original_xml is not None:
            return rewrite_xdc(profile, original_xml, f"{profile.id}.xdc", node_id=stored.info.node_id,
                               values=values), "application/xml"
        text = export_xdd(profile, node_id=stored.info.node_id, values=values, xdc=True).decode("utf-8")
        return text, "application/xml"
    raise InvalidValue(_("Unknown format '{format}' (formats: {formats})").format(format=fmt,
                                                                                  formats=", ".join(FORMATS)))


def guess_format(filename: str, text: str) -> str:
    lowered = filename.lower()
    for fmt in FORMATS:
        if lowered.endswith("." + fmt):
            return fmt
    stripped = text.lstrip()
    if stripped.startswith("{"):
        return "json"
    if stripped.startswith("[") or stripped.startswith(";"):
        return "dcf"
    return "csv"


def import_any(data: bytes, filename: str, profiles: ProfileLookup, *, fmt: str | None = None,
               profile_id: str | None = None, name: str | None = None) -> ImportedSet:
    """A file of any of the formats (``fmt``, else guessed from the name and the first characters)."""
    text = decode_text(data, filename)
    chosen = fmt or guess_format(filename, text)
    if chosen == "json":
        imported = import_json(text, profiles, source=filename)
        if profile_id and imported.profile.id != profile_id:
            raise SetImportError(filename, [LineError(None, None, _("the file is for profile '{profile}', not "
                                                                    "'{wanted}'").format(profile=imported.profile.id,
                                                                                         wanted=profile_id))])
        if name:
            imported.name = name
        return imported
    if chosen == "csv":
        return import_csv(text, profiles, profile_id=profile_id, name=name, source=filename)
    if chosen == "dcf":
        return import_dcf(text, profiles, profile_id=profile_id, name=name, source=filename)
    raise InvalidValue(_("Unknown format '{format}' (formats: {formats})").format(format=chosen,
                                                                                  formats=", ".join(FORMATS)))


def file_name(stored: StoredSet, fmt: str) -> str:
    """``Conveyor_1-v3.json``: the set's name made safe for a file name."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", stored.info.name).strip("_") or f"set-{stored.info.id}"
    return f"{safe}-v{stored.version}.{fmt}"
