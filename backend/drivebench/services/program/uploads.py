"""Firmware files checked and waiting to be sent: kept in memory for the node they were checked against, a few at a
time (a download names one by its id; a file never reaches a node it was not checked for)."""

from __future__ import annotations

import threading
import uuid
from collections import OrderedDict
from dataclasses import dataclass

from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.program.firmware import FirmwareFile

KEEP = 8


@dataclass(frozen=True)
class Checked:
    id: str
    session_id: str
    node_id: int
    firmware: FirmwareFile


class CheckedFiles:
    def __init__(self, keep: int = KEEP) -> None:
        self._keep = keep
        self._files: OrderedDict[str, Checked] = OrderedDict()
        self._lock = threading.Lock()

    def add(self, session_id: str, node_id: int, firmware: FirmwareFile) -> Checked:
        checked = Checked(uuid.uuid4().hex[:12], session_id, node_id, firmware)
        with self._lock:
            self._files[checked.id] = checked
            while len(self._files) > self._keep:
                self._files.popitem(last=False)
        return checked

    def get(self, file_id: str, session_id: str, node_id: int) -> Checked:
        with self._lock:
            checked = self._files.get(file_id)
        if checked is None or (checked.session_id, checked.node_id) != (session_id, node_id):
            raise NotFound(_("No checked firmware file '{file}' for node {node}: upload the file again (checked "
                             "files are kept for a while)").format(file=file_id, node=node_id))
        return checked


CHECKED = CheckedFiles()
