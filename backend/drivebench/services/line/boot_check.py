"""Boot-up check (CiA 302-2, "boot slave"): per planned node read 0x1000 and 0x1018 sub 1-4 and compare them with
the line project's expected identity (the master's 0x1F84 device type, 0x1F85 vendor, 0x1F86 product code, 0x1F87
revision, 0x1F88 serial); a node that does not answer is missing, an error where the project marks it mandatory
(0x1F81 bit 3), a warning where optional. The nodes are read side by side: a silent node costs its own SDO timeout,
never the others'."""

from __future__ import annotations

import asyncio
from typing import Literal

from pydantic import BaseModel

from drivebench.errors import DriveBenchError, InvalidValue, SdoAbortError
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session
from drivebench.services.line.project import LineProject, ProjectNode
from drivebench.services.params import reads
from drivebench.services.params.jobs import said

CheckStatus = Literal["ok", "differs", "missing", "unverified"]

IDENTITY_OBJECTS: dict[str, tuple[int, int]] = {
    "device_type": (0x1000, 0), "vendor_id": (0x1018, 1), "product_code": (0x1018, 2), "revision": (0x1018, 3),
    "serial": (0x1018, 4)}


def _object_name(key: str) -> str:
    names = {"device_type": _("device type"), "vendor_id": _("vendor id"), "product_code": _("product code"),
             "revision": _("revision"), "serial": _("serial number")}
    return names[key]


class NodeBootCheck(BaseModel):
    node_id: int
    name: str
    mandatory: bool
    status: CheckStatus
    read: dict[str, str]
    """What the node answered, ``0x0000003B`` per object."""
    messages: list[str]
    """One sentence per difference (or the one that says all is well)."""


class BootCheck(BaseModel):
    project: str
    session_id: str
    ok: bool
    """Every mandatory node answered with the project's identity (optional ones may be missing)."""
    nodes: list[NodeBootCheck]


async def _read_one(session: Session, node_id: int, index: int, subindex: int) -> int:
    """One identity object: through the Parameters read path where the node is in the session (its profile, the
    session's locks and retries), else as the scan reads a node it does not know yet."""
    if node_id in session.nodes:
        ref = f"0x{index:04X}" if subindex == 0 else f"0x{index:04X}.{subindex}"
        value = await reads.read(session, node_id, ref)
        if isinstance(value.raw, int):
            return value.raw
        if isinstance(value.raw, bytes):  # an index the profile does not list is read as bytes
            return int.from_bytes(value.raw[:4], "little")
        raise InvalidValue(_("{ref} answered {value}, not a number").format(ref=ref, value=value.display))
    data = await session.client(node_id).aupload(index, subindex)
    return int.from_bytes(data[:4], "little")


async def read_identity(session: Session, node_id: int) -> tuple[dict[str, int], dict[str, str]]:
    """(values read, why an object could not be read). A node silent at 0x1000 is not asked the rest."""
    found: dict[str, int] = {}
    unread: dict[str, str] = {}
    for key, (index, subindex) in IDENTITY_OBJECTS.items():
        try:
            found[key] = await _read_one(session, node_id, index, subindex)
        except SdoAbortError as exc:
            unread[key] = said(exc)
        except DriveBenchError as exc:
            unread[key] = said(exc)
            if key == "device_type":
                break
    return found, unread


def _hex(value: int) -> str:
    return f"0x{value:08X}"


def _differences(node: ProjectNode, found: dict[str, int]) -> list[str]:
    expected = node.identity
    said: list[str] = []
    for key, wanted in (("device_type", expected.device_type), ("vendor_id", expected.vendor_id),
                        ("product_code", expected.product_code), ("serial", expected.serial)):
        if wanted is None:
            continue
        if key not in found:
            said.append(_("node {node}: {object} could not be read; the project expects {expected}.").format(
                node=node.node_id, object=_object_name(key), expected=_hex(wanted)))
        elif found[key] != wanted:
            said.append(_("node {node}: {object} {found} differs from the project's {expected}.").format(
                node=node.node_id, object=_object_name(key), found=_hex(found[key]), expected=_hex(wanted)))
    low, high = expected.revision_min, expected.revision_max
    if low is not None or high is not None:
        revision = found.get("revision")
        shown_range = _("{low} to {high}").format(low=_hex(low) if low is not None else "0x00000000",
                                                  high=_hex(high) if high is not None else "0xFFFFFFFF")
        if revision is None:
            said.append(_("node {node}: revision could not be read; the project expects {range}.").format(
                node=node.node_id, range=shown_range))
        elif (low is not None and revision < low) or (high is not None and revision > high):
            said.append(_("node {node}: revision {found} is outside the project's range {range}.").format(
                node=node.node_id, found=_hex(revision), range=shown_range))
    return said


async def check_node(session: Session, node: ProjectNode) -> NodeBootCheck:
    found, unread = await read_identity(session, node.node_id)
    read = {key: _hex(value) for key, value in found.items()}
    base = {"node_id": node.node_id, "name": node.name, "mandatory": node.mandatory, "read": read}
    if "device_type" not in found and "vendor_id" not in found:
        words = (_("node {node} missing (mandatory): no answer to 0x1000 ({why}).") if node.mandatory
                 else _("node {node} missing (optional): no answer to 0x1000 ({why})."))
        return NodeBootCheck(status="missing", messages=[words.format(
            node=node.node_id, why=unread.get("device_type", "-"))], **base)
    differences = _differences(node, found)
    if differences:
        return NodeBootCheck(status="differs", messages=differences, **base)
    checked = node.identity.model_dump(exclude_none=True)
    if not checked:
        return NodeBootCheck(status="unverified", messages=[_(
            "node {node} answers; the project states no identity to compare.").format(node=node.node_id)], **base)
    return NodeBootCheck(status="ok", messages=[_("node {node} answers with the project's identity.").format(
        node=node.node_id)], **base)


async def boot_check(project: LineProject, session: Session) -> BootCheck:
    """Every project node checked, side by side."""
    if session.ethercat is not None:
        raise InvalidValue(_("The boot-up check reads CANopen identities by SDO; session '{session}' is an EtherCAT "
                             "line.").format(session=session.name))
    results = await asyncio.gather(*(check_node(session, node) for node in project.nodes))
    ok = all(result.status in ("ok", "unverified") or (result.status == "missing" and not result.mandatory)
             for result in results)
    return BootCheck(project=project.name, session_id=session.id, ok=ok, nodes=list(results))
