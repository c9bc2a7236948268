"""The EtherCAT state machine (ESM, ETG.1000.6) and the master object dictionary a mailbox gateway reaches at
station address 0.

AL status register values: 1 Init, 2 Pre-Operational, 3 Bootstrap, 4 Safe-Operational, 8 Operational; bit 4 (0x10)
set = error indication (the slave refused a state change or left a state on its own; the AL status code says why).
The AL status code texts are those of the 8400 motec EtherCAT manual (EDS84DMOTECAT, §7.3, the complete list it
gives); codes it does not list are named by ETG.1000.6's general meaning.

Master object dictionary (ETG.5001.1 "modular device profile" for the master, used by ETG.1510 diagnosis). What the
standard's public users agree on (Beckhoff's TwinCAT device manager table, acontis' EC_T_OBJAXXX, the ETG.1510 client
pyetg1510): per configured slave number ``n`` (0-based, in the order of the configured address list)

* ``0x8000 + n`` configuration data: sub 1 station address (UINT16), sub 3 name (STRING), sub 5 vendor id,
  sub 6 product code, sub 7 revision, sub 8 serial number (UINT32 each);
* ``0xA000 + n`` diagnosis data: sub 1 AL status (register 0x130), sub 2 AL control (register 0x120),
  sub 3 last AL status code (UINT16 each);
* ``0xF020`` configured address list: sub 0 number of slaves, sub ``n + 1`` station address of slave ``n``.

Our reading (what the texts we could check do not settle): a state change is requested by writing the wanted state
to AL control (``0xA000 + n`` sub 2), and the master answers once the slave has reached it or refused it (then the
AL status has the error bit and sub 3 the code); masters that keep AL control read-only answer the write with an abort,
which the tool reports in words.
"""

from __future__ import annotations

from collections.abc import Collection
from enum import IntEnum

from drivebench.i18n import _

MASTER_STATION = 0
CONFIGURATION_BASE = 0x8000
DIAGNOSIS_BASE = 0xA000
ADDRESS_LIST = 0xF020
MAX_SLAVES = 0x1000

SUB_STATION, SUB_NAME, SUB_VENDOR, SUB_PRODUCT, SUB_REVISION, SUB_SERIAL = 1, 3, 5, 6, 7, 8
SUB_AL_STATUS, SUB_AL_CONTROL, SUB_AL_STATUS_CODE = 1, 2, 3
ERROR_FLAG = 0x10


class EsmState(IntEnum):
    INIT = 1
    PRE_OPERATIONAL = 2
    BOOTSTRAP = 3
    SAFE_OPERATIONAL = 4
    OPERATIONAL = 8

    @property
    def label(self) -> str:
        return {1: "Init", 2: "Pre-Operational", 3: "Bootstrap", 4: "Safe-Operational", 8: "Operational"}[self.value]

    @classmethod
    def parse(cls, text: str) -> EsmState:
        key = text.strip().lower().replace("_", "-").replace(" ", "-")
        for state in cls:
            if key in (state.label.lower(), state.name.lower().replace("_", "-"), str(state.value)):
                return state
        aliases = {"preop": cls.PRE_OPERATIONAL, "pre-op": cls.PRE_OPERATIONAL, "safeop": cls.SAFE_OPERATIONAL,
                   "safe-op": cls.SAFE_OPERATIONAL, "op": cls.OPERATIONAL, "boot": cls.BOOTSTRAP}
        if key in aliases:
            return aliases[key]
        raise ValueError(_("'{text}' is no EtherCAT state: Init, Pre-Operational, Safe-Operational or Operational")
                         .format(text=text))


AL_STATUS_CODES = {
    0x0000: "No error",
    0x0011: "Invalid status change requested",
    0x0012: "Unknown status requested",
    0x0013: "\"Bootstrap\" status is not supported",
    0x0016: "Invalid mailbox configuration \"Pre-operational\"",
    0x001A: "Synchronisation error",
    0x001B: "Sync manager watchdog",
    0x001D: "Invalid output data configuration",
    0x001E: "Invalid input data configuration",
    0x002B: "Invalid input and output data",
    0x0030: "Invalid configuration of DC synchronisation",
    0x9001: "Firmware watchdog error",
    0x9002: "Mapping error",
}
"""The 8400 motec EtherCAT manual's AL status codes (§7.3), its words (shown as the manual prints them, like the
texts a profile brings; the tool's own words around them are translated when shown)."""


def al_status_code_text(code: int) -> str:
    text = AL_STATUS_CODES.get(code)
    if text is not None:
        return text
    if code >= 0x8000:
        return _("vendor-specific AL status code 0x{code:04X}").format(code=code)
    return _("AL status code 0x{code:04X}").format(code=code)


def al_status_text(status: int, code: int = 0) -> str:
    """``Safe-Operational``, or ``Pre-Operational + error: Invalid status change requested (0x0011)``."""
    try:
        state = EsmState(status & 0x0F).label
    except ValueError:
        state = _("unknown state 0x{state:X}").format(state=status & 0x0F)
    if status & ERROR_FLAG:
        return _("{state} + error: {text} (0x{code:04X})").format(state=state, text=al_status_code_text(code),
                                                                   code=code)
    return state


MANDATORY_STATES = frozenset({EsmState.INIT, EsmState.PRE_OPERATIONAL, EsmState.SAFE_OPERATIONAL,
                              EsmState.OPERATIONAL})
"""What every slave has (ETG.1000.6); Bootstrap is optional: a device's profile says whether it has it."""
UPWARDS = (EsmState.INIT, EsmState.PRE_OPERATIONAL, EsmState.SAFE_OPERATIONAL, EsmState.OPERATIONAL)

INVALID_CHANGE, UNKNOWN_STATE, NO_BOOTSTRAP = 0x0011, 0x0012, 0x0013


def transition_refusal(current: EsmState, target: int, supported: Collection[EsmState] = MANDATORY_STATES
                       ) -> int | None:
    """The AL status code a slave answers a requested state change with, or None if it may change (ETG.1000.6:
    up one step at a time, Init -> Pre-Op -> Safe-Op -> Op; down to any lower state; Bootstrap only from and back
    to Init). ``supported``: the states the device has (its profile's ``ethercat`` section)."""
    try:
        wanted = EsmState(target)
    except ValueError:
        return UNKNOWN_STATE
    if wanted not in supported:
        return NO_BOOTSTRAP if wanted is EsmState.BOOTSTRAP else UNKNOWN_STATE
    if wanted is current:
        return None
    if EsmState.BOOTSTRAP in (wanted, current):
        return None if EsmState.INIT in (wanted, current) else INVALID_CHANGE
    if UPWARDS.index(wanted) > UPWARDS.index(current) + 1:
        return INVALID_CHANGE
    return None
