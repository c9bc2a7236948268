"""A device's control and status words as its profile describes them (``control`` section, see
:mod:`drivebench.device.control`): state from the status word, the next control word of a command.

A profile without a ``control`` section whose objects have 0x6040/0x6041 is a CiA 402 drive by its standard
(:func:`drivebench.device.cia402.generic_section`); anything else has no drive control the panel knows.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from drivebench.device import cia402
from drivebench.device.catalog import Catalog
from drivebench.device.control import Command, ControlSection, StateBox
from drivebench.device.profile import Profile

__all__ = ["COMMAND_LABELS", "Command", "Family", "family_of", "next_control_word", "state_label"]

COMMAND_LABELS = {
    Command.SHUTDOWN: "Shutdown", Command.SWITCH_ON: "Switch on", Command.ENABLE_OPERATION: "Enable operation",
    Command.DISABLE_OPERATION: "Disable operation", Command.QUICK_STOP: "Quick stop",
    Command.DISABLE_VOLTAGE: "Disable voltage", Command.FAULT_RESET: "Fault reset",
}


@dataclass(frozen=True, eq=False)
class Family:
    """The drive control of one profile: its ``control`` section and the state decoding it selects."""

    section: ControlSection

    @property
    def key(self) -> str:
        return self.section.key

    @property
    def title(self) -> str:
        return self.section.title

    @property
    def note(self) -> str:
        return self.section.note

    @property
    def control_ref(self) -> str:
        return self.section.control_word

    @property
    def status_ref(self) -> str:
        return self.section.status_word

    @property
    def states(self) -> list[StateBox]:
        return self.section.states

    @property
    def generic(self) -> bool:
        """The standard CiA 402 section of a device without a vendor control section."""
        return self.section.key == "cia402-generic"

    @cached_property
    def moving(self) -> frozenset[Command]:
        return frozenset(self.section.moving_commands)

    def state_of(self, status_word: int) -> str:
        if self.section.state_machine == "cia402":
            return next((state for mask, value, state in cia402.STATE_MASKS if status_word & mask == value),
                        "unknown")
        if self.section.state_machine == "lenze":  # device status in bits 8...11
            return self.section.state_codes.get(status_word >> 8 & 0x0F, "unknown")
        return "unknown"

    def state_box(self, key: str) -> StateBox | None:
        return next((box for box in self.section.states if box.key == key), None)


_FAMILIES: dict[int, tuple[Profile, Family | None]] = {}


def family_of_profile(profile: Profile) -> Family | None:
    cached = _FAMILIES.get(id(profile))
    if cached is not None and cached[0] is profile:
        return cached[1]
    if profile.control is not None:
        found: Family | None = Family(profile.control) if profile.control.state_machine != "none" else None
    elif cia402.has_drive_words(profile):
        found = Family(cia402.generic_section(profile))
    else:
        found = None
    _FAMILIES[id(profile)] = (profile, found)
    return found


def family_of(catalog: Catalog | None) -> Family | None:
    """The device control a profile offers (None: the device has no control word the panel knows)."""
    return None if catalog is None else family_of_profile(catalog.profile)


def state_label(family: Family, key: str) -> str:
    box = family.state_box(key)
    return box.label if box else "Unknown state"


def next_control_word(family: Family, command: Command, last: int) -> int:
    bits = family.section.commands[command]
    return (last & ~bits.clear & 0xFFFF) | bits.set
