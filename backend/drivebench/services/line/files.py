"""A line project as a file: JSON (the model's own form) and lely's YAML master configuration (``dcfgen``).

A file that does not parse is refused with the file, the line and the reason (nothing is stored): JSON syntax errors
carry their line, a value the model refuses is found in the text by its path (the file is composed as YAML, a
superset of the JSON a person writes, only to find the line), YAML errors carry PyYAML's mark.

YAML: the lely keys where a project field maps (``master.node_id``, ``master.baudrate`` [kbit/s], per slave ``dcf``,
``node_id``, ``vendor_id``, ``product_code``, ``revision_number`` (the lowest revision), ``serial_number``,
``mandatory``, ``software_version`` (a numeric firmware version) and ``sdo`` (index, sub_index, value: the
parameter set and the PDO set-up)); what lely has no key for is in each slave's ``drivebench`` block.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import yaml
from pydantic import ValidationError

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.line.project import (
    LineProject,
    ProfileRef,
    ProjectNode,
    ProjectSet,
    Values,
)

Address = tuple[int, int]
Addresser = Callable[[ProjectNode, str], Address | None]
"""The (index, sub-index) of a ref in the node's profile (None: unknown)."""
Namer = Callable[[ProjectNode, int, int], str]
"""The ref of an (index, sub-index) in the node's profile (``0x2000.1`` where the profile does not list it)."""


class ProjectFileError(InvalidValue):
    """A project file that does not parse: where and why."""


def _refused(filename: str, line: int | None, reason: str) -> ProjectFileError:
    if line is None:
        return ProjectFileError(_("{file}: {reason}").format(file=filename, reason=reason))
    return ProjectFileError(_("{file}, line {line}: {reason}").format(file=filename, line=line, reason=reason))


def _line_of(text: str, path: Sequence[int | str]) -> int | None:
    """The line (1-based) of the value at ``path`` in a JSON or YAML text, or of the deepest part of it found."""
    try:
        node = yaml.compose(text)
    except yaml.YAMLError:
        return None
    line = node.start_mark.line + 1 if node is not None else None
    for part in path:
        if isinstance(node, yaml.MappingNode):
            found = next((value for key, value in node.value if key.value == str(part)), None)
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and part < len(node.value):
            found = node.value[part]
        else:
            found = None
        if found is None:
            break
        node, line = found, found.start_mark.line + 1
    return line


def _validated(data: object, text: str, filename: str, path_of: Callable[[tuple[Any, ...]], Sequence[int | str]]
               ) -> LineProject:
    try:
        return LineProject.model_validate(data).sorted()
    except ValidationError as exc:
        raise _invalid(exc, text, filename, path_of) from exc


def _invalid(exc: ValidationError, text: str, filename: str,
             path_of: Callable[[tuple[Any, ...]], Sequence[int | str]]) -> ProjectFileError:
    """The first problem pydantic found, at its line, named by its path in the file."""
    first = exc.errors()[0]
    path = path_of(tuple(first["loc"]))
    where = " > ".join(str(part) for part in path)
    reason = f"{where}: {first['msg']}" if where else str(first["msg"])
    return _refused(filename, _line_of(text, path), reason)


# --- JSON ----------------------------------------------------------------------------------------------------
def to_json(project: LineProject) -> str:
    return project.sorted().model_dump_json(indent=2) + "\n"


def from_json(content: bytes | str, filename: str = "project.json") -> LineProject:
    text = content.decode("utf-8", errors="replace") if isinstance(content, bytes) else content
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _refused(filename, exc.lineno, exc.msg) from exc
    return _validated(data, text, filename, lambda loc: loc)


# --- lely YAML -----------------------------------------------------------------------------------------------
class _Hex(int):
    """An int YAML writes as hex (identities, indices)."""


def _hex_repr(dumper: yaml.SafeDumper, value: _Hex) -> yaml.ScalarNode:
    return dumper.represent_scalar("tag:yaml.org,2002:int", f"0x{int(value):04X}")


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(_Hex, _hex_repr)


def _slave_key(node: ProjectNode, taken: set[str]) -> str:
    base = re.sub(r"[^0-9a-zA-Z_]+", "_", node.name).strip("_").lower() or "node"
    key = f"{base}_{node.node_id}"
    while key in taken or key in ("master", "options"):
        key += "_"
    taken.add(key)
    return key


def _sdo(node: ProjectNode, address: Addresser) -> list[dict[str, Any]]:
    entries = []
    for ref, raw in node.set_values().items():
        found = address(node, ref)
        if found is not None:
            entries.append({"index": _Hex(found[0]), "sub_index": found[1], "value": raw})
    return entries


def _identity(value: int | None) -> dict[str, Any]:
    return {} if value is None else {"value": _Hex(value)}


def to_yaml(project: LineProject, address: Addresser) -> str:
    """lely dcfgen's master configuration; ``address`` finds each value's object (values it cannot place are left
    out of ``sdo`` and stay in the JSON file only)."""
    project = project.sorted()
    baud = {node.baud_kbit for node in project.nodes}
    document: dict[str, Any] = {"master": {"node_id": project.master.node_id,
                                           **({"baudrate": baud.pop()} if len(baud) == 1 else {})}}
    document["master"]["drivebench"] = {"schema_version": project.schema_version, "name": project.name,
                                        "cable": project.cable.model_dump() if project.cable else None}
    taken: set[str] = set()
    for node in project.nodes:
        identity = node.identity
        slave: dict[str, Any] = {"dcf": f"{node.profile.id}.eds" if node.profile else None, "node_id": node.node_id}
        for key, value in (("vendor_id", identity.vendor_id), ("product_code", identity.product_code),
                           ("revision_number", identity.revision_min), ("serial_number", identity.serial)):
            if value is not None:
                slave[key] = _Hex(value)
        slave["mandatory"] = node.mandatory
        if node.firmware_version is not None and node.firmware_version.isdigit():
            slave["software_version"] = int(node.firmware_version)
        slave["sdo"] = _sdo(node, address)
        slave["drivebench"] = {
            "name": node.name, "device": node.device, "baud_kbit": node.baud_kbit, "channels": node.channels,
            "pdo_ids": node.pdo_ids, "device_type": _Hex(identity.device_type) if identity.device_type is not None
            else None, "revision_max": _Hex(identity.revision_max) if identity.revision_max is not None else None,
            "firmware_version": node.firmware_version,
            "profile": node.profile.model_dump() if node.profile else None,
            "parameter_set": ({"name": node.parameter_set.name, "set_id": node.parameter_set.set_id}
                              if node.parameter_set else None)}
        document[_slave_key(node, taken)] = slave
    return yaml.dump(document, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=120)


def _node_from_slave(key: str, slave: dict[str, Any], default_baud: int | None, name: Namer,
                     is_pdo: Callable[[int], bool]) -> dict[str, Any]:
    extra = slave.get("drivebench") or {}
    if not isinstance(extra, dict):
        raise ValueError(_("its 'drivebench' block is not a mapping"))
    profile = extra.get("profile")
    dcf = slave.get("dcf")
    if profile is None and isinstance(dcf, str):
        profile = {"id": re.sub(r"\.(eds|dcf|xdd|xdc|json)$", "", dcf, flags=re.IGNORECASE), "sha256": ""}
    device = extra.get("device") or (profile or {}).get("id") or key
    node: dict[str, Any] = {
        "node_id": slave.get("node_id"), "name": extra.get("name", key), "device": device,
        "baud_kbit": extra.get("baud_kbit", default_baud), "mandatory": slave.get("mandatory", False),
        "channels": extra.get("channels"), "pdo_ids": extra.get("pdo_ids", "canopen"),
        "identity": {"device_type": extra.get("device_type"), "vendor_id": slave.get("vendor_id"),
                     "product_code": slave.get("product_code"), "revision_min": slave.get("revision_number"),
                     "revision_max": extra.get("revision_max"), "serial": slave.get("serial_number")},
        "profile": profile, "firmware_version": extra.get("firmware_version", (
            str(slave["software_version"]) if slave.get("software_version") is not None else None))}
    shell = ProjectNode.model_validate({**node, "profile": None, "identity": {}})
    values: Values = {}
    pdo: Values = {}
    for entry in slave.get("sdo") or []:
        index, sub = int(entry["index"]), int(entry.get("sub_index", 0))
        ref = name(shell, index, sub) if profile is None else name(
            shell.model_copy(update={"profile": ProfileRef.model_validate(profile)}), index, sub)
        (pdo if is_pdo(index) else values)[ref] = entry["value"]
    parameter_set = extra.get("parameter_set")
    if parameter_set is not None or values:
        node["parameter_set"] = {**ProjectSet(name=key).model_dump(exclude={"values"}), **(parameter_set or {}),
                                 "values": values}
    node["pdo"] = pdo
    return node


def from_yaml(content: bytes | str, filename: str, name: Namer, is_pdo: Callable[[int], bool]) -> LineProject:
    """A lely-style master configuration as a project (``name`` turns each ``sdo`` entry's object into a ref)."""
    text = content.decode("utf-8", errors="replace") if isinstance(content, bytes) else content
    try:
        document = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        raise _refused(filename, mark.line + 1 if mark else None, str(exc.problem or exc.context)) from exc
    except yaml.YAMLError as exc:
        raise _refused(filename, None, str(exc)) from exc
    if not isinstance(document, dict):
        raise _refused(filename, 1, _("a master configuration is a mapping of 'master' and one key per slave"))
    master = document.get("master") or {}
    extra = master.get("drivebench") if isinstance(master, dict) else None
    if not isinstance(master, dict) or not isinstance(extra or {}, dict):
        raise _refused(filename, _line_of(text, ["master"]), _("'master' is a mapping (node_id, baudrate)"))
    extra = extra or {}
    keys = [key for key in document if key not in ("master", "options")]
    nodes = []
    for key in keys:
        slave = document[key]
        if not isinstance(slave, dict):
            raise _refused(filename, _line_of(text, [key]), _("slave '{key}' is not a mapping").format(key=key))
        try:
            nodes.append(_node_from_slave(str(key), slave, master.get("baudrate"), name, is_pdo))
        except ValidationError as exc:
            raise _invalid(exc, text, filename, partial(_slave_path, str(key))) from exc
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            reason = _("an sdo entry needs index, sub_index and value ({why})").format(why=exc)
            raise _refused(filename, _line_of(text, [key, "sdo"]), f"{key}: {reason}") from exc
    data = {"schema_version": extra.get("schema_version", 1), "name": extra.get("name", filename),
            "master": {"node_id": master.get("node_id", 1)}, "cable": extra.get("cable"),
            "nodes": nodes}

    def path_of(loc: tuple[Any, ...]) -> Sequence[int | str]:
        if len(loc) >= 2 and loc[0] == "nodes" and isinstance(loc[1], int) and loc[1] < len(keys):
            return [keys[loc[1]], *_yaml_path(loc[2:])]
        return ["master"]
    return _validated(data, text, filename, path_of)


def _slave_path(key: str, loc: tuple[Any, ...]) -> list[int | str]:
    return [key, *_yaml_path(loc)]


def _yaml_path(loc: tuple[Any, ...]) -> list[int | str]:
    """A model path inside a node as the YAML slave writes it."""
    lely = {("node_id",): "node_id", ("mandatory",): "mandatory", ("identity", "vendor_id"): "vendor_id",
            ("identity", "product_code"): "product_code", ("identity", "revision_min"): "revision_number",
            ("identity", "serial"): "serial_number"}
    for prefix, key in lely.items():
        if tuple(loc[:len(prefix)]) == prefix:
            return [key]
    return ["drivebench", *(str(part) for part in loc)]

