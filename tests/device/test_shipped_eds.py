"""The EDS files shipped beside the JSON profiles (``device_profiles/eds/``): up to date, readable by our importer
and by canopen, and lossless for what an EDS carries.

Regenerate them with ``python -m drivebench.device.formats.build_eds`` after editing a profile.
"""

from __future__ import annotations

import io
from functools import cache
from pathlib import Path

import canopen
import pytest

from drivebench.config import settings
from drivebench.device.formats.build_eds import EDS_SUBDIR, build, eds_path, shipped_profiles
from drivebench.device.formats.eds import import_eds, resolve_node_expr
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import load_profile_file
from drivebench.device.profiles.profile import ObjectEntry, Parameter, Profile, Value
from drivebench.protocol.datatypes import DataType

JSON_FILES = sorted(p.name for p in settings.profiles_dir.glob("*.json"))
NODE_ID = 5
# Profile fields an EDS has no key for (DriveBench-only knowledge: cross references, selection texts, groups, motion
# marks - CiA 402 objects get theirs again from the standard - and process-data marks, which parameter sets use).
NOT_IN_EDS = {"code", "selection", "bits", "reset_required", "group", "motion", "live"}
PARAMETER_FIELDS = ["data_type", "access", "unit", "factor", "min", "max", "default", "pdo_mappable", "description"]


@cache
def _profile(name: str) -> Profile:
    path = settings.profiles_dir / name
    return load_profile_file(path.read_bytes(), name)


@cache
def _exported(name: str) -> str:
    return export_eds(_profile(name))


@cache
def _imported(name: str) -> Profile:
    return import_eds(_exported(name), source=f"{_profile(name).id}.eds")


def _eds_fields(entry: ObjectEntry) -> dict[str, object]:
    return entry.model_dump(exclude=NOT_IN_EDS)


def test_every_shipped_profile_has_an_eds_and_no_eds_is_stale() -> None:
    assert len(JSON_FILES) >= 5
    ids = {_profile(name).id for name in JSON_FILES}
    shipped = {p.stem for p in (settings.profiles_dir / EDS_SUBDIR).glob("*.eds")}
    assert shipped == ids, "run: python -m drivebench.device.formats.build_eds"
    assert [p.id for p in shipped_profiles()] == [_profile(name).id for name in JSON_FILES]


@pytest.mark.parametrize("name", JSON_FILES)
def test_shipped_eds_is_up_to_date(name: str) -> None:
    path = eds_path(_profile(name))
    assert path.is_file(), f"{path} is missing; run: python -m drivebench.device.formats.build_eds"
    assert path.read_text(encoding="utf-8") == _exported(name), (
        f"{path.name} differs from what {name} exports; run: python -m drivebench.device.formats.build_eds")


@pytest.mark.parametrize("name", JSON_FILES)
def test_our_importer_reads_the_shipped_file(name: str) -> None:
    profile = _profile(name)
    path = eds_path(profile)
    again = import_eds(path, source=path.name)
    assert again == _imported(name)
    assert (again.id, again.family, again.version, again.source) == (
        profile.id, profile.family, profile.version, profile.source)
    assert again.notes == profile.notes
    ident = profile.identity.model_dump(exclude={"device_type"})
    assert again.identity.model_dump(exclude={"device_type"}) == ident
    assert again.identity.device_type == (profile.identity.device_type or 0)
    assert again.features.baud_rates_kbit == profile.features.baud_rates_kbit
    assert (again.features.rpdo_count, again.features.tpdo_count) == (
        profile.features.rpdo_count, profile.features.tpdo_count)


@pytest.mark.parametrize("name", JSON_FILES)
def test_import_of_export_round_trips_the_objects(name: str) -> None:
    profile = _profile(name)
    again = {(o.index, o.subindex): o for o in _imported(name).objects}
    for obj in profile.objects:
        assert (obj.index, obj.subindex) in again, f"0x{obj.index:04X}sub{obj.subindex}"
        assert _eds_fields(again[(obj.index, obj.subindex)]) == _eds_fields(obj), f"0x{obj.index:04X}sub{obj.subindex}"


@pytest.mark.parametrize("name", JSON_FILES)
def test_vendor_parameters_become_objects_at_their_index(name: str) -> None:
    profile = _profile(name)
    again = {(o.index, o.subindex): o for o in _imported(name).objects}
    own = {(o.index, o.subindex) for o in profile.objects}
    checked = 0
    for item in Catalog(profile).items:
        if not isinstance(item.entry, Parameter) or (item.index, item.subindex) in own:
            continue
        exported = again[(item.index, item.subindex)]
        assert exported.model_dump(include=set(PARAMETER_FIELDS)) == item.entry.model_dump(
            include=set(PARAMETER_FIELDS)), item.ref
        assert exported.code == item.entry.code or exported.name.startswith(item.ref), item.ref
        checked += 1
    assert checked == len({(i.index, i.subindex) for i in Catalog(profile).items
                           if isinstance(i.entry, Parameter)} - own)


def _raw(entry: ObjectEntry, value: Value | None) -> object:
    if value is None:
        return None
    if isinstance(value, str):
        return bytes.fromhex(value) if entry.data_type is DataType.OCTET_STRING else value
    if entry.data_type.is_integer:
        return round(value * entry.factor)
    return value * entry.factor


@pytest.mark.parametrize("name", JSON_FILES)
def test_canopen_reads_the_shipped_file_losslessly(name: str) -> None:
    path = eds_path(_profile(name))
    stream = io.StringIO(path.read_text(encoding="utf-8"))
    stream.name = path.name
    od = canopen.import_od(stream, node_id=NODE_ID)
    entries = _imported(name).objects
    assert {i for i in od if isinstance(i, int) and i >= 0x1000} == {o.index for o in entries}
    for entry in entries:
        where = f"0x{entry.index:04X}sub{entry.subindex}"
        obj = od[entry.index]
        if isinstance(obj, canopen.objectdictionary.ODVariable):
            assert entry.object_type == "VAR", where
            var = obj
        else:
            kind = "ARRAY" if isinstance(obj, canopen.objectdictionary.ODArray) else "RECORD"
            assert (entry.object_type, obj.name) == (kind, entry.object_name), where
            var = obj[entry.subindex]
        default = resolve_node_expr(entry.default_expr, NODE_ID) if entry.default_expr else _raw(entry, entry.default)
        assert (var.name, var.data_type, var.access_type, var.pdo_mappable) == (
            entry.name, entry.data_type.code, entry.access.value, entry.pdo_mappable), where
        limits = (_raw(entry, entry.min), _raw(entry, entry.max))
        if entry.data_type.is_float:  # canopen reads LowLimit/HighLimit as integers only (eds.py: int(text, 0))
            limits = (None, None)
        assert (var.default, var.min, var.max) == (default, *limits), where
        assert (var.factor, var.unit, var.description) == (
            entry.factor, entry.unit or "", entry.description or ""), where


def test_build_writes_only_what_changed(tmp_path: Path) -> None:
    source = settings.profiles_dir / JSON_FILES[0]
    (tmp_path / source.name).write_bytes(source.read_bytes())
    written = build(tmp_path)
    assert [p.name for p in written] == [f"{_profile(JSON_FILES[0]).id}.eds"]
    assert written[0].read_text(encoding="utf-8") == _exported(JSON_FILES[0])
    assert build(tmp_path) == []
