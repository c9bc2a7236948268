"""The program download objects of CiA 302-3 and what their values mean, in words.

0x1F50 program data (DOMAIN), 0x1F51 program control (write: 0 stop, 1 start, 2 reset, 3 clear; read: 0 stopped,
1 started, 3 no program), 0x1F56 program software identification (UNSIGNED32, the device's own identification of
the program it holds, often a CRC), 0x1F57 flash status identification (UNSIGNED32: bit 0 "in progress", bits 1-7
an error code, bits 8-15 reserved, bits 16-31 manufacturer specific). Sub-index 1 is program number 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from drivebench.i18n import N_, Text

PROGRAM_DATA = 0x1F50
PROGRAM_CONTROL = 0x1F51
SOFTWARE_ID = 0x1F56
FLASH_STATUS = 0x1F57
PROGRAM_OBJECTS = frozenset({PROGRAM_DATA, PROGRAM_CONTROL, 0x1F52, 0x1F53, 0x1F54, 0x1F55, SOFTWARE_ID, FLASH_STATUS})
"""What a device in its bootloader still answers (CiA 302-3 lists 0x1F50 ... 0x1F57)."""


class ProgramCommand(IntEnum):
    """What a write to 0x1F51 asks for."""

    STOP = 0
    START = 1
    RESET = 2
    CLEAR = 3


PROGRAM_STATES = {0: N_("program stopped"), 1: N_("program running"), 3: N_("no program")}

FLASH_ERRORS: dict[int, str] = {
    0: N_("no error"),
    1: N_("no valid program"),
    2: N_("data format unknown"),
    3: N_("data format error or data CRC error"),
    4: N_("flash not cleared before write"),
    5: N_("flash write error"),
    6: N_("general address error"),
    7: N_("flash secured (write access currently not allowed)"),
}
"""Error codes of 0x1F57 bits 1-7 (CiA 302-3; 8-63 reserved, 64-127 manufacturer specific)."""


@dataclass(frozen=True)
class FlashStatus:
    raw: int

    @property
    def in_progress(self) -> bool:
        return bool(self.raw & 0x01)

    @property
    def error(self) -> int:
        return (self.raw >> 1) & 0x7F

    @property
    def ok(self) -> bool:
        return not self.in_progress and self.error == 0

    def text(self) -> str:
        if self.in_progress:
            return Text(N_("flash operation in progress"))
        code = self.error
        if code in FLASH_ERRORS:
            return Text(FLASH_ERRORS[code])
        if code >= 64:
            return Text(N_("manufacturer-specific flash error {code}"), code=code)
        return Text(N_("reserved flash error code {code}"), code=code)


def program_state_text(raw: int) -> str:
    known = PROGRAM_STATES.get(raw)
    return Text(known) if known else Text(N_("program state {value} (manufacturer specific)"), value=raw)
