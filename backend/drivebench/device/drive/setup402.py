"""The generic CiA 402 set-up: a guided sequence any profile with the drive words (0x6040/0x6041) gets, built from
the standard objects it lists (CiA 402-2: modes, software limits, speed limits, ramps, factor group, homing).

Each step is a ``parameter`` step on the standard object with the profile's default as the proposal (the form shows
the present value; the user's value wins), written by the checked write and read back. An object the profile does
not list, or lists read-only, gets no step; the sequence names the missing ones.
"""

from __future__ import annotations

from drivebench.device.drive import cia402
from drivebench.device.drive.control import Sequence, Step
from drivebench.device.profiles.catalog import index_ref
from drivebench.device.profiles.profile import ObjectEntry, Profile
from drivebench.i18n import N_, _

KEY = "cia402-setup"

STANDARD: tuple[tuple[int, int, str], ...] = (
    (0x6060, 0, N_("modes of operation")),
    (0x607D, 1, N_("software position limit, minimum")),
    (0x607D, 2, N_("software position limit, maximum")),
    (0x6080, 0, N_("max motor speed")),
    (0x607F, 0, N_("max profile velocity")),
    (0x6083, 0, N_("profile acceleration")),
    (0x6084, 0, N_("profile deceleration")),
    (0x6085, 0, N_("quick stop deceleration")),
    (0x608F, 1, N_("position encoder resolution: encoder increments")),
    (0x608F, 2, N_("position encoder resolution: motor revolutions")),
    (0x6090, 1, N_("velocity encoder resolution: encoder increments per second")),
    (0x6090, 2, N_("velocity encoder resolution: motor revolutions per second")),
    (0x6091, 1, N_("gear ratio: motor revolutions")),
    (0x6091, 2, N_("gear ratio: shaft revolutions")),
    (0x6092, 1, N_("feed constant: feed")),
    (0x6092, 2, N_("feed constant: shaft revolutions")),
    (0x6098, 0, N_("homing method")),
    (0x6099, 1, N_("homing speed during search for switch")),
    (0x6099, 2, N_("homing speed during search for zero")),
    (0x609A, 0, N_("homing acceleration")),
)
"""The standard objects of the set-up, in the order CiA 402-2 sets a drive up, with their standard names."""


def _writable(profile: Profile) -> dict[tuple[int, int], ObjectEntry]:
    return {(obj.index, obj.subindex or 0): obj for obj in profile.objects if obj.access.writable}


def offered(profile: Profile) -> bool:
    """A CiA 402 drive (0x6040/0x6041) listing, writable, at least one of the set-up's objects beyond the mode (a
    drive with 0x6060 alone, such as a frequency inverter's velocity mode, has nothing to set up here)."""
    found = _writable(profile)
    return cia402.has_drive_words(profile) and any((index, sub) in found for index, sub, _name in STANDARD
                                                   if index != 0x6060)


def setup_sequence(profile: Profile) -> Sequence:
    """The set-up of ``profile``'s drive in the reader's language: one step per standard object it lists."""
    found = _writable(profile)
    steps: list[Step] = []
    absent: list[str] = []
    for index, sub, name in STANDARD:
        ref = index_ref(index, sub)
        entry = found.get((index, sub))
        if entry is None:
            absent.append(f"{ref} {_(name)}")
            continue
        proposal = entry.default if isinstance(entry.default, int | float) else None
        steps.append(Step(title=f"{ref}: {_(name)}", kind="parameter", ref=ref, proposal=proposal,
                          note=_modes_note(profile) if index == 0x6060 else None))
    missing = [_("Not listed (or read-only) in this device's profile, so not offered: {objects}.").format(
        objects=", ".join(absent))] if absent else []
    return Sequence(key=KEY, title=_("CiA 402 set-up (modes, limits, ramps, factor group, homing)"),
                    source=_("CiA 402-2 (IEC 61800-7-201) standard objects as this device's profile lists them"),
                    preconditions=[_("The drive is not enabled (switch on disabled or ready): limits, factor group "
                                     "and homing take effect on the next move."),
                                   _("Each proposal is the profile's default; enter the machine's values.")],
                    missing=missing, steps=steps)


def _modes_note(profile: Profile) -> str | None:
    modes = cia402.listed_modes(profile)
    supported = next((obj.default for obj in profile.objects if obj.index == 0x6502 and not obj.subindex), None)
    if isinstance(supported, int):
        modes = cia402.modes_from_6502(supported)
    if not modes:
        return None
    return _("Modes this drive supports (0x6502 or its object dictionary): {modes}.").format(
        modes=", ".join(f"{mode} {cia402.mode_label(mode)}" for mode in modes))
