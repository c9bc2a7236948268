"""The master's side of a line project as a CiA 302 master keeps it (CiA 302-2): per node 0x1F81 NMT slave
assignment and the expected identity 0x1F84 device type, 0x1F85 vendor, 0x1F86 product code, 0x1F87 revision,
0x1F88 serial number (sub-index = the node id; 0: not checked), as a concise DCF for the master's 0x1F22."""

from __future__ import annotations

import base64

from drivebench.device.formats.concise_dcf import ConciseEntry, encode
from drivebench.i18n import N_, _
from drivebench.services.line.project import LineProject, ProjectNode
from drivebench.services.sets.concise_sets import ConciseLine, ConcisePreview

IS_SLAVE = 1 << 0
BOOT_SLAVE = 1 << 2
MANDATORY = 1 << 3
"""0x1F81 bits: the node is an NMT slave, the master boots it (checks and configures it), it is mandatory."""

MASTER_OBJECTS = {0x1F81: N_("NMT slave assignment"), 0x1F84: N_("Device type identification"),
                  0x1F85: N_("Vendor identification"), 0x1F86: N_("Product code"), 0x1F87: N_("Revision number"),
                  0x1F88: N_("Serial number")}


def assignment(node: ProjectNode) -> int:
    return IS_SLAVE | BOOT_SLAVE | (MANDATORY if node.mandatory else 0)


def master_entries(project: LineProject) -> list[ConciseEntry]:
    """Object by object, node by node (0x1F87: the lowest revision the project accepts)."""
    entries = []
    for index in MASTER_OBJECTS:
        for node in sorted(project.nodes, key=lambda n: n.node_id):
            identity = node.identity
            value = {0x1F81: assignment(node), 0x1F84: identity.device_type, 0x1F85: identity.vendor_id,
                     0x1F86: identity.product_code, 0x1F87: identity.revision_min, 0x1F88: identity.serial}[index]
            entries.append(ConciseEntry(index, node.node_id, (value or 0).to_bytes(4, "little")))
    return entries


def master_preview(project: LineProject) -> ConcisePreview:
    entries = master_entries(project)
    data = encode(entries)
    lines = [ConciseLine(index=entry.index, subindex=entry.subindex,
                         ref=f"0x{entry.index:04X}.{entry.subindex}", name=_(MASTER_OBJECTS[entry.index]),
                         size=len(entry.data), data=entry.data.hex(" "),
                         value=f"0x{int.from_bytes(entry.data, 'little'):08X}") for entry in entries]
    return ConcisePreview(node_id=project.master.node_id, count=len(entries), size=len(data), lines=lines,
                          base64=base64.b64encode(data).decode())
