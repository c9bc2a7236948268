"""A CiA 302-3 program download slave written from the standard alone, on canopen's LocalNode: shares no code with
DriveBench's simulator. canopen's SDO server refuses block download (CiA 301 allows that), so a master must fall
back to segmented transfer. Its software identification (0x1F56) is the Adler-32 of the image, not a CRC32: a master
must read it, never compute it."""

from __future__ import annotations

import zlib

import canopen
from canopen.objectdictionary import ObjectDictionary, ODVariable
from canopen.objectdictionary.datatypes import DOMAIN, UNSIGNED8, UNSIGNED32
from canopen.sdo.exceptions import SdoAbortedError


def _variable(name: str, index: int, subindex: int, data_type: int, access: str, default: int | None = None
              ) -> ODVariable:
    variable = ODVariable(name, index, subindex)
    variable.data_type = data_type
    variable.access_type = access
    if default is not None:
        variable.default = default
    return variable


def _array(od: ObjectDictionary, name: str, index: int, data_type: int, access: str, default: int | None) -> None:
    record = canopen.objectdictionary.ODRecord(name, index)
    record.add_member(_variable("highest sub-index", index, 0, UNSIGNED8, "const", 1))
    record.add_member(_variable(f"{name} 1", index, 1, data_type, access, default))
    od.add_object(record)


class ProgramSlave:
    """0x1F50 DOMAIN (wo), 0x1F51 program control (rw: 0 stop, 1 start, 3 clear), 0x1F56 (ro), 0x1F57 (ro)."""

    def __init__(self, network: canopen.Network, node_id: int) -> None:
        od = ObjectDictionary()
        for name, index, data_type, access, default in (
                ("Program data", 0x1F50, DOMAIN, "rw", None), ("Program control", 0x1F51, UNSIGNED8, "rw", 1),
                ("Program software identification", 0x1F56, UNSIGNED32, "ro", 0),
                ("Flash status identification", 0x1F57, UNSIGNED32, "ro", 0)):
            _array(od, name, index, data_type, access, default)
        self.node = canopen.LocalNode(node_id, od)
        network.add_node(self.node)
        self.image = b"original"
        self.running = True
        self.node.add_write_callback(self._written)
        self.node.add_read_callback(self._read)

    def _read(self, index: int, subindex: int, od: object) -> int | None:
        if (index, subindex) == (0x1F56, 1):
            return zlib.adler32(self.image)
        if (index, subindex) == (0x1F51, 1):
            return 1 if self.running else 0
        return None

    def _written(self, index: int, subindex: int, od: object, data: bytes) -> None:
        if (index, subindex) == (0x1F50, 1):
            if self.running:
                raise SdoAbortedError(0x08000022)
            self.image = bytes(data)
        elif (index, subindex) == (0x1F51, 1):
            command = data[0]
            if command == 0:
                self.running = False
            elif command == 1:
                self.running = True
            elif command != 3:
                raise SdoAbortedError(0x06090030)
