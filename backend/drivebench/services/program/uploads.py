"""Firmware files checked and waiting to be sent: kept in the database for the node they were checked against (a
download names one by its id; a file never reaches a node it was not checked for), the newest few per node, so a
download, or the New line wizard's program step, still finds its file after a server restart or on another server
sharing the database."""

from __future__ import annotations

import uuid
from dataclasses import dataclass

from sqlalchemy import delete, select

from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.program.firmware import FirmwareFile
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import CheckedFirmwareRow

KEEP = 8
"""Checked files kept per node; an older one must be checked again."""


@dataclass(frozen=True)
class Checked:
    id: str
    session_id: str
    node_id: int
    firmware: FirmwareFile


class CheckedFiles:
    def __init__(self, url: str | None = None, keep: int = KEEP) -> None:
        self.url = url
        self._keep = keep

    def add(self, session_id: str, node_id: int, firmware: FirmwareFile) -> Checked:
        checked = Checked(uuid.uuid4().hex[:12], session_id, node_id, firmware)
        with transaction(self.url) as db:
            db.add(CheckedFirmwareRow(id=checked.id, session_id=session_id, node_id=node_id, name=firmware.name,
                                      kind=firmware.kind, image=firmware.image, start_address=firmware.start_address,
                                      identity=dict(firmware.identity)))
            db.flush()
            kept = select(CheckedFirmwareRow.id).where(
                CheckedFirmwareRow.session_id == session_id, CheckedFirmwareRow.node_id == node_id).order_by(
                CheckedFirmwareRow.created.desc(), CheckedFirmwareRow.id).limit(self._keep)
            db.execute(delete(CheckedFirmwareRow).where(
                CheckedFirmwareRow.session_id == session_id, CheckedFirmwareRow.node_id == node_id,
                CheckedFirmwareRow.id.not_in(kept.scalar_subquery())))
        return checked

    def get(self, file_id: str, session_id: str, node_id: int) -> Checked:
        with transaction(self.url) as db:
            row = db.get(CheckedFirmwareRow, file_id)
            if row is None or (row.session_id, row.node_id) != (session_id, node_id):
                raise NotFound(_("No checked firmware file '{file}' for node {node}: upload the file again (checked "
                                 "files are kept for a while)").format(file=file_id, node=node_id))
            firmware = FirmwareFile(row.name, row.kind, row.image, row.start_address, dict(row.identity))
        return Checked(row.id, row.session_id, row.node_id, firmware)


CHECKED = CheckedFiles()
