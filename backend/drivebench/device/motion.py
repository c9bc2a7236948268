"""Which writes can make a drive move: the profile's ``motion`` mark of an object or parameter, else the standard.

A profile marks its control words, setpoints, modes and command/setpoint sources (:class:`~drivebench.device.profile.
Motion`). Objects the standards define are marked here by their index, so a drive whose profile came from an
uploaded EDS is covered with no code change:

* CiA 402 (every axis: a device with several axes repeats the objects at +0x800 per axis, up to 0x9FFF): 0x6040
  control word, 0x6060 modes of operation, the targets 0x6042 / 0x60FF (velocity), 0x6071 (torque), 0x607A
  (position), 0x60C1 (interpolation data), 0x6052 (vl nominal percentage), 0x60B1 / 0x60B2 (velocity / torque offset);
* CiA 301 / 302: 0x1F80 NMT startup (a device told to start itself enters Operational and acts on process data) and
  0x1F25 configuration request (configures and, as CiA 302 has it, may start the slave). Every write of these two
  needs the confirmation: CiA 301 and CiA 302 read bit 2 of 0x1F80 differently, so no value is taken as harmless.

What a *still* value is (decided here, see :data:`CIA402_STILL`): a control word that clears "enable operation" or
"enable voltage", or requests quick stop, cannot start the motor, whatever the state before (CiA 402 state machine:
no transition into operation enabled without bits 0...3 = 1 and bit 2 = 1); such writes (shutdown 0x06, switch on
0x07, disable voltage, quick stop) pass without confirmation and are never refused, as stopping a machine never is.
A velocity or torque setpoint of 0 cannot speed a drive up. A position target has no still value (0 is a position).
"""

from __future__ import annotations

from drivebench.device.catalog import Item
from drivebench.device.profile import Motion, StillValue
from drivebench.device.scaling import RawValue

CIA402_STILL = [
    StillValue(value=0x0000, mask=0x0008, meaning="enable operation (bit 3) cleared"),
    StillValue(value=0x0000, mask=0x0002, meaning="enable voltage (bit 1) cleared"),
    StillValue(value=0x0000, mask=0x0004, meaning="quick stop (bit 2 = 0)"),
]
ZERO = [StillValue(value=0, meaning="setpoint 0")]
CIA402_AXIS_SPAN = 0x800
CIA402_OBJECTS: dict[int, Motion] = {
    0x6040: Motion(kind="control_word", still=CIA402_STILL),
    0x6060: Motion(kind="mode"),
    0x6042: Motion(kind="setpoint", still=ZERO),
    0x6052: Motion(kind="setpoint", still=ZERO),
    0x60FF: Motion(kind="setpoint", still=ZERO),
    0x6071: Motion(kind="setpoint", still=ZERO),
    0x60B1: Motion(kind="setpoint", still=ZERO),
    0x60B2: Motion(kind="setpoint", still=ZERO),
    0x607A: Motion(kind="setpoint"),
    0x60C1: Motion(kind="setpoint"),
}
"""By index, every subindex (0x60C1 is a record of interpolation data)."""
CIA301_OBJECTS: dict[int, Motion] = {0x1F80: Motion(kind="start"), 0x1F25: Motion(kind="start")}


def standard_motion(index: int, subindex: int) -> Motion | None:
    """The mark the standards give an object (None: writing it cannot move a drive by itself)."""
    if 0x6000 <= index < 0xA000:
        base = 0x6000 + (index - 0x6000) % CIA402_AXIS_SPAN
        if base == 0x60C1 and subindex == 0:  # the record's number of entries
            return None
        return CIA402_OBJECTS.get(base)
    return CIA301_OBJECTS.get(index)


def motion_of(item: Item) -> Motion | None:
    """The profile's own mark first, else the standard's."""
    return item.entry.motion or standard_motion(item.index, item.subindex)


def is_still(motion: Motion, raw: RawValue) -> bool:
    """True when writing ``raw`` cannot make the drive move (one of the mark's still values)."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return False
    if isinstance(raw, float):  # a REAL32 setpoint: only an exact 0 with a still value 0
        return raw == 0 and any(still.value == 0 and still.mask is None for still in motion.still)
    return any((raw & still.mask if still.mask is not None else raw) == still.value for still in motion.still)


def moves(item: Item, raw: RawValue) -> Motion | None:
    """The mark when writing ``raw`` to ``item`` can make the drive move, else None."""
    motion = motion_of(item)
    return None if motion is None or is_still(motion, raw) else motion
