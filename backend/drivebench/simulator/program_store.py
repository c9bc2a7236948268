"""Program download on a simulated device (CiA 302-3): 0x1F50 program data, 0x1F51 program control, 0x1F56 software
identification (the CRC32 of the image held), 0x1F57 flash status; in front of the node's object store.

The image arrives whole (the SDO server collects a block or segmented transfer, then writes it). A download is
taken only while the program is stopped or absent (CiA 302-3); start needs a valid program. Faults (``faults.py``):
``flash_error`` makes the next flash fail with that 0x1F57 error code; ``power_loss_mid_flash`` cuts the power while
the image is flashed: the device comes back in its bootloader (no valid program), where only 0x1F50 ... 0x1F57 answer.
"""

from __future__ import annotations

import threading
import zlib
from collections.abc import Callable

from drivebench.protocol.canopen.program_objects import (
    FLASH_STATUS,
    PROGRAM_CONTROL,
    PROGRAM_DATA,
    PROGRAM_OBJECTS,
    SOFTWARE_ID,
    ProgramCommand,
)
from drivebench.protocol.canopen.sdo_server import ObjectAccess, SdoAbort
from drivebench.simulator.faults import FaultState

OBJECT_MISSING = 0x06020000
SUB_MISSING = 0x06090011
WRITE_ONLY = 0x06010001
READ_ONLY = 0x06010002
CANNOT_STORE = 0x08000020
DEVICE_STATE = 0x08000022
STOPPED, RUNNING, NO_PROGRAM = 0, 1, 3
NO_VALID_PROGRAM = 1


class ProgramStore:
    """The node's program objects; every other object is the store's (refused while in the bootloader)."""

    def __init__(self, objects: ObjectAccess, faults: FaultState, image: bytes,
                 power_cut: Callable[[], None]) -> None:
        self._objects = objects
        self._faults = faults
        self._power_cut = power_cut
        self._lock = threading.Lock()
        self.image = image
        self.state = RUNNING
        self.flash_error = 0
        self.bootloader = False
        self.downloads = 0

    @property
    def software_id(self) -> int:
        return zlib.crc32(self.image) if self.image else 0

    # --- ObjectAccess ---------------------------------------------------------------------------------------
    def read(self, index: int, subindex: int) -> bytes:
        if index not in PROGRAM_OBJECTS:
            if self.bootloader:
                raise SdoAbort(DEVICE_STATE)
            return self._objects.read(index, subindex)
        if index not in (PROGRAM_DATA, PROGRAM_CONTROL, SOFTWARE_ID, FLASH_STATUS):
            raise SdoAbort(OBJECT_MISSING)
        if subindex == 0:
            return b"\x01"
        if subindex != 1:
            raise SdoAbort(SUB_MISSING)
        with self._lock:
            if index == PROGRAM_DATA:
                raise SdoAbort(WRITE_ONLY)
            if index == PROGRAM_CONTROL:
                return bytes([self.state])
            if index == SOFTWARE_ID:
                return self.software_id.to_bytes(4, "little")
            return (self.flash_error << 1).to_bytes(4, "little")

    def write(self, index: int, subindex: int, data: bytes) -> None:
        if index not in PROGRAM_OBJECTS:
            if self.bootloader:
                raise SdoAbort(DEVICE_STATE)
            self._objects.write(index, subindex, data)
            return
        if subindex == 0:
            raise SdoAbort(READ_ONLY)
        if subindex != 1:
            raise SdoAbort(SUB_MISSING)
        if index == PROGRAM_DATA:
            self._flash(data)
        elif index == PROGRAM_CONTROL:
            self._control(data)
        else:
            raise SdoAbort(READ_ONLY if index in (SOFTWARE_ID, FLASH_STATUS) else OBJECT_MISSING)

    # --- behaviour ------------------------------------------------------------------------------------------
    def _flash(self, data: bytes) -> None:
        faults = self._faults.faults
        with self._lock:
            if self.state == RUNNING:
                raise SdoAbort(DEVICE_STATE, "program running: stop it (0x1F51 = 0) before a download")
            if faults.power_loss_mid_flash:
                self._faults.set(power_loss_mid_flash=False)
                self.image, self.state, self.flash_error, self.bootloader = b"", NO_PROGRAM, NO_VALID_PROGRAM, True
                self._power_cut()
                return
            if faults.flash_error is not None:
                self.flash_error = faults.flash_error
                self._faults.set(flash_error=None)
                self.image, self.state = b"", NO_PROGRAM
                raise SdoAbort(CANNOT_STORE)
            self.image, self.flash_error, self.state = bytes(data), 0, STOPPED
            self.downloads += 1

    def _control(self, data: bytes) -> None:
        if len(data) < 1:
            raise SdoAbort(0x06070013)
        try:
            command = ProgramCommand(data[0])
        except ValueError as exc:
            raise SdoAbort(0x06090030) from exc
        with self._lock:
            if command is ProgramCommand.STOP:
                if self.state == RUNNING:
                    self.state = STOPPED
            elif command in (ProgramCommand.START, ProgramCommand.RESET):
                if not self.image or self.flash_error:
                    self.flash_error = self.flash_error or NO_VALID_PROGRAM
                    raise SdoAbort(DEVICE_STATE, "no valid program to start")
                self.state, self.bootloader = RUNNING, False
            else:  # clear
                if self.state == RUNNING:
                    raise SdoAbort(DEVICE_STATE, "program running: stop it before clearing")
                self.image, self.state, self.flash_error = b"", NO_PROGRAM, NO_VALID_PROGRAM
