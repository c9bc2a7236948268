"""The object list a slave reports through the CoE SDO information service, against its profile: which objects the
device has that the profile lacks, and which the profile lists that the device does not have (Info tab).

Only CoE (EtherCAT) slaves offer the service; a CANopen node's object list comes from its EDS, and a slave without
the service says so in words (its mailbox answers "the service is not supported").
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from drivebench.errors import Conflict, DriveBenchError
from drivebench.i18n import _
from drivebench.protocol.ethercat.coe_sdo import CoeSdoClient
from drivebench.services.bus.sessions import Session


@dataclass(frozen=True)
class ListedObject:
    index: int
    ref: str
    """The profile's name for the index (``C00039``, ``0x1018``), or the code its addressing gives it."""
    name: str
    kind: str = ""
    """VAR, ARRAY or RECORD (from the device's object description)."""
    max_subindex: int | None = None


@dataclass(frozen=True)
class ObjectListComparison:
    device_count: int
    profile_count: int
    common: int
    only_device: list[ListedObject]
    only_profile: list[ListedObject]


async def compare(session: Session, node_id: int) -> ObjectListComparison:
    node = session.node(node_id)
    client = session.client(node_id).sdo_information
    if client is None:
        raise Conflict(_("Node {node} is a CANopen node: the SDO information service is CoE's (EtherCAT); a CANopen "
                         "node's object list is its EDS (Profiles page).").format(node=node_id))
    catalog = node.catalog
    device = await asyncio.to_thread(client.information, CoeSdoClient.od_list)
    listed: dict[int, ListedObject] = {}
    for item in catalog.items if catalog else []:
        if item.index not in listed:
            ref = item.ref.split("/")[0].split(".")[0]
            listed[item.index] = ListedObject(item.index, ref, item.entry.name)
    only_device = []
    for index in device:
        if index in listed:
            continue
        ref = catalog.vendor_ref(index, 0) if catalog else f"0x{index:04X}"
        try:
            described = await asyncio.to_thread(
                client.information, lambda sdo, index=index: sdo.object_description(index), index)
            only_device.append(ListedObject(index, ref, described.name, described.object_code_text,
                                            described.max_subindex))
        except DriveBenchError as exc:
            only_device.append(ListedObject(index, ref, f"– ({exc.detail})"))
    reported = set(device)
    return ObjectListComparison(device_count=len(device), profile_count=len(listed),
                                common=len(reported & set(listed)), only_device=only_device,
                                only_profile=[obj for index, obj in sorted(listed.items()) if index not in reported])
