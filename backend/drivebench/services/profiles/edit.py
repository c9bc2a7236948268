"""Editing an uploaded EDS/DCF/XDD/XDC profile, and its regenerated EDS and XDD: the file written over the upload,
so what nobody edited stays as it was read (:mod:`drivebench.device.formats.eds_rewrite`,
:mod:`drivebench.device.formats.xdd_rewrite`)."""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

from drivebench.device.formats.dcf_patch import file_encoding
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.eds_rewrite import rewrite_eds
from drivebench.device.formats.xdd import XML_SUFFIXES
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.device.formats.xdd_rewrite import rewrite_xdd
from drivebench.device.profiles.loader import LoadedFile, ProfileRegistry
from drivebench.device.profiles.profile import ObjectEntry, Profile, Value
from drivebench.errors import Conflict, ProfileError, UnknownParameter
from drivebench.i18n import _

EDS_SUFFIXES = (".eds", ".dcf")
VALUE_KEYS = {"DefaultValue": "default", "LowLimit": "min", "HighLimit": "max", "ParameterValue": "parameter_value"}
"""EDS key -> the field that holds its value."""
VALUE_FIELDS = set(VALUE_KEYS.values())
KEPT_TEXT_FIELDS = {**VALUE_KEYS, "ParameterName": "name"}
"""EDS key -> the field whose edit replaces the file's kept text of it (``value_texts``)."""


class ObjectEdit(BaseModel):
    """The fields of one object an edit may set (engineering units, as the profile holds them); a field left out
    stays, ``null`` clears it."""

    model_config = ConfigDict(extra="forbid")

    name: str | None = None
    default: Value | None = None
    min: int | float | None = None
    max: int | float | None = None
    parameter_value: Value | None = None
    denotation: str | None = None
    unit: str | None = None
    description: str | None = None


def regenerated_eds(loaded: LoadedFile) -> tuple[bytes, str]:
    """The EDS of a loaded profile and its media type: written over its EDS/DCF file where it came from one
    (in that file's encoding), else written from the profile (UTF-8)."""
    if loaded.original is not None and loaded.suffix in EDS_SUFFIXES:
        content = rewrite_eds(loaded.profile, loaded.original, f"{loaded.profile.id}{loaded.suffix}")
        return content, f"text/plain; charset={file_encoding(loaded.original)[0]}"
    return export_eds(loaded.profile).encode("utf-8"), "text/plain; charset=utf-8"


def regenerated_xdd(loaded: LoadedFile) -> bytes:
    """The XDD of a loaded profile: written over its XDD/XDC file where it came from one, else from the profile."""
    if loaded.original is not None and loaded.suffix in XML_SUFFIXES:
        return rewrite_xdd(loaded.profile, loaded.original, f"{loaded.profile.id}{loaded.suffix}")
    return export_xdd(loaded.profile)


def _written_over(loaded: LoadedFile, profile: Profile) -> bytes:
    """``profile`` written over the file ``loaded`` came from (an EDS/DCF or an XDD/XDC)."""
    assert loaded.original is not None
    source = f"{profile.id}{loaded.suffix}"
    if loaded.suffix in XML_SUFFIXES:
        return rewrite_xdd(profile, loaded.original, source)
    return rewrite_eds(profile, loaded.original, source)


def _check_value(entry: ObjectEntry, field: str, value: Value | None) -> None:
    """A value an edit sets must be one of the object's data type (engineering units; raw = value * factor)."""
    data_type = entry.data_type
    if value is None or (data_type.is_string and isinstance(value, str)):
        return
    number = value if isinstance(value, int | float) and not isinstance(value, bool) else None
    try:
        raw = None if number is None else number * entry.factor
        whole = isinstance(raw, int) or (raw is not None and float(raw).is_integer())
        finite = raw is not None and (isinstance(raw, int) or math.isfinite(raw))
        if data_type.is_float and raw is not None:
            finite = math.isfinite(float(raw))
    except OverflowError:
        raw, whole, finite = None, False, False
    limits = data_type.raw_limits()
    fits = raw is not None and finite and (data_type.is_float or (
        data_type.is_integer and whole and (limits is None or limits[0] <= raw <= limits[1])))
    if not fits:
        low, high = limits or ("", "")
        raise ProfileError(_("{field}: {value!r} is not a {type} value{range}").format(
            field=field, value=value, type=data_type.value,
            range=f" ({low}..{high})" if limits else ""), source=f"0x{entry.index:04X}sub{entry.subindex}")


def edited(profile: Profile, index: int, subindex: int, edit: ObjectEdit) -> Profile:
    """``profile`` with one object changed; a value that does not fit the object is a ProfileError in words."""
    objects = list(profile.objects)
    at = next((n for n, o in enumerate(objects) if (o.index, o.subindex) == (index, subindex)), None)
    if at is None:
        raise UnknownParameter(_("{object} is not an object of '{profile}'").format(
            object=f"0x{index:04X}sub{subindex}", profile=profile.id))
    changes: dict[str, Any] = edit.model_dump(include=edit.model_fields_set)
    for field in VALUE_FIELDS & changes.keys():
        _check_value(objects[at], field, changes[field])
    if "default" in changes:
        changes["default_expr"] = None
    texts = {key: text for key, text in (objects[at].value_texts or {}).items()
             if KEPT_TEXT_FIELDS.get(key) not in changes}  # the file's text of an edited value is replaced
    changes["value_texts"] = texts or None
    try:
        objects[at] = ObjectEntry.model_validate({**objects[at].model_dump(), **changes})
        return Profile.model_validate({**profile.model_dump(), "objects": objects})
    except ValidationError as exc:
        raise ProfileError(exc.errors()[0]["msg"].removeprefix("Value error, "), source=profile.id) from exc


def is_editable(registry: ProfileRegistry, profile_id: str) -> bool:
    """Whether a profile is an uploaded EDS/DCF/XDD/XDC, the only kinds :func:`edit_object` changes."""
    loaded = registry.loaded(profile_id)
    return not registry.is_builtin(profile_id) and loaded.original is not None and loaded.suffix in (
        *EDS_SUFFIXES, *XML_SUFFIXES)


def edit_object(registry: ProfileRegistry, profile_id: str, index: int, subindex: int, edit: ObjectEdit
                ) -> Profile:
    """Change one object of an uploaded EDS/DCF/XDD/XDC profile: the stored file is written over with only the
    keys (attributes, elements) of that change (blocking: run it in a thread)."""
    loaded = registry.loaded(profile_id)
    if not is_editable(registry, profile_id) or loaded.original is None:
        raise Conflict(_("'{profile}' is not an uploaded EDS/DCF/XDD/XDC; only those are edited here").format(
            profile=profile_id))
    profile = edited(loaded.profile, index, subindex, edit)
    content = _written_over(loaded, profile)
    name = registry.uploaded_as(profile_id) or f"{profile_id}{loaded.suffix}"
    return registry.add_upload(name, content)
