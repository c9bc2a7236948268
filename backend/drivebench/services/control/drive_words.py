"""A device's control and status words as its profile describes them (``control`` section, see
:mod:`drivebench.device.drive.control`): state from the status word, the next control word of a command.

A profile without a ``control`` section whose objects have 0x6040/0x6041 is a CiA 402 drive by its standard
(:func:`drivebench.device.drive.cia402.generic_section`); anything else has no drive control the panel knows.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from drivebench.device.drive import cia402
from drivebench.device.drive.control import Command, ControlSection, StateBox
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.catalog_cache import ProfileCache
from drivebench.device.profiles.profile import Profile
from drivebench.i18n import N_, Text, _

__all__ = ["COMMAND_LABELS", "Command", "Family", "command_label", "family_of", "next_control_word", "state_label",
           "state_text"]

COMMAND_LABELS = {  # DriveBench's names of the commands (CiA 402's): command_label() gives them translated
    Command.SHUTDOWN: N_("Shutdown"), Command.SWITCH_ON: N_("Switch on"),
    Command.ENABLE_OPERATION: N_("Enable operation"), Command.DISABLE_OPERATION: N_("Disable operation"),
    Command.QUICK_STOP: N_("Quick stop"), Command.DISABLE_VOLTAGE: N_("Disable voltage"),
    Command.FAULT_RESET: N_("Fault reset"),
}


def command_label(command: Command) -> str:
    return _(COMMAND_LABELS[command])


@dataclass(frozen=True, eq=False)
class Family:
    """The drive control of one profile: its ``control`` section and the state decoding it selects."""

    section: ControlSection

    @property
    def key(self) -> str:
        return self.section.key

    @property
    def title(self) -> str:
        return cia402.shown(self.section.title)

    @property
    def note(self) -> str:
        return cia402.shown(self.section.note)

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

    @staticmethod
    def shown(text: str) -> str:
        """A text of the section as the panel shows it: a standard (CiA 402) name in the reader's language, a
        vendor's own text as its manual prints it."""
        return cia402.shown(text)

    def state_box(self, key: str) -> StateBox | None:
        return next((box for box in self.section.states if box.key == key), None)


def _family(profile: Profile) -> Family | None:
    if profile.control is not None:
        return Family(profile.control) if profile.control.state_machine != "none" else None
    if cia402.has_drive_words(profile):
        return Family(cia402.generic_section(profile))
    return None


family_of_profile: ProfileCache[Family | None] = ProfileCache(_family)
"""The drive control of a profile, built once per profile object (bounded like the catalogues)."""


def family_of(catalog: Catalog | None) -> Family | None:
    """The device control a profile offers (None: the device has no control word the panel knows)."""
    return None if catalog is None else family_of_profile(catalog.profile)


def state_label(family: Family, key: str) -> str:
    """The state's name as the panel shows it (a standard name in the reader's language)."""
    box = family.state_box(key)
    return cia402.shown(box.label) if box else _("Unknown state")


def state_text(family: Family, key: str) -> str:
    """:func:`state_label` kept for readers of any language (a scope marker, made once): a standard name as a
    :class:`~drivebench.i18n.Text` (``shown()`` puts it into the reader's language), a vendor profile's own name
    as it is."""
    box = family.state_box(key)
    if box is None:
        return Text(N_("Unknown state"))
    if box.label in cia402.STANDARD_TEXTS and box.label not in cia402.OWN_MSGID:
        return Text(box.label)
    return box.label


def next_control_word(family: Family, command: Command, last: int) -> int:
    bits = family.section.commands[command]
    return (last & ~bits.clear & 0xFFFF) | bits.set
