"""Which writes can make a drive move: the profile's ``motion`` mark of an object or parameter, and the standard's.

A profile marks its control words, setpoints, modes and command/setpoint sources
(:class:`~drivebench.device.profiles.profile.Motion`). Objects the standards define are marked here by their index, so a
drive whose profile came from an uploaded EDS is covered with no code change, and a profile can add marks but never
weaken these:

* CiA 402 (every axis: a device with several axes repeats the objects at +0x800 per axis, up to 0x9FFF): 0x6040
  control word, 0x6060 modes of operation, the targets 0x6042 / 0x60FF (velocity), 0x6071 (torque), 0x607A
  (position), 0x60C1 (interpolation data), 0x6052 (vl nominal percentage), 0x60B1 / 0x60B2 (velocity / torque offset);
* CiA 301 / 302: 0x1F80 NMT startup (a device told to start itself enters Operational and acts on process data),
  0x1F25 configuration request (configures and, as CiA 302 has it, may start the slave) and 0x1F51 program control
  (CiA 302-3: 1 starts the program). Every write of these needs the confirmation: CiA 301 and CiA 302 read bit 2
  of 0x1F80 differently, so no value is taken as harmless.

What a *still* value is (issue 27): a write that cannot make the drive move **from any state** it may be in.

* A control word is still only when it holds a *blocking* bit and not the fault-reset bit. The blocking bits come
  from the control section's commands (:func:`word_rule`): a bit that a stopping command (shutdown, disable
  operation, quick stop, disable voltage) forces to the level opposite to the one ``enable_operation`` needs (CiA
  402: bits 0...3 cleared; 8400: SwitchOn or EnableOperation cleared, SetQuickStop or SetCInh set; EMF2178IB: QSP
  or CINH set). No state machine enters "operation enabled" while such a bit holds. The fault bits (8400 SetFail,
  EMF2178IB TRIP-SET) are no blocking bits: they raise a fault that the next reset clears, and the drive then
  follows the rest of the word. A fault reset is never still: a reset drive may restart by itself.
  A profile's still value counts only if every word it matches holds a blocking bit; the others are ignored
  (:func:`ignored_still_values` lists them in words, the profile loader logs them). A profile control word without
  a control section (no commands to judge it by) has no still value.
* A setpoint is still only at 0 (a whole-value 0, no mask). A position target has no still value (0 is a position).
* Other marks (a mode, a command source, a start command): only whole values (no mask) the profile lists.
* A standard object is judged by the standard; a profile's still values for it only count where the standard's
  do too (a profile can make it stricter, never weaker).

The judgement is by the value alone, never by the drive's present state: a state read before the write may be
stale by the time the word arrives, so it could only add refusals, and a stop word must pass without one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from drivebench.device.drive import cia402
from drivebench.device.drive.control import Command, CommandBits, ControlSection
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.profile import Entry, Motion, Profile, StillValue
from drivebench.device.profiles.scaling import RawValue

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
CIA301_OBJECTS: dict[int, Motion] = {0x1F80: Motion(kind="start"), 0x1F25: Motion(kind="start"),
                                     0x1F51: Motion(kind="start")}
STOPPING = (Command.SHUTDOWN, Command.DISABLE_OPERATION, Command.QUICK_STOP, Command.DISABLE_VOLTAGE)
WORD_BITS = 32


@dataclass(frozen=True)
class WordRule:
    """What a control word's bits do, read from a control section's commands."""

    blocking: tuple[tuple[int, int], ...]
    """(bit, level): while the word holds it, the drive cannot be enabled from any state."""
    fault_reset: int
    """The fault-reset bits: a word with one of them set is never still."""

    def blocks(self, raw: int) -> bool:
        return not raw & self.fault_reset and any((raw >> bit & 1) == level for bit, level in self.blocking)

    def sound(self, still: StillValue) -> bool:
        """Every word ``still`` matches holds a blocking bit."""
        mask = still.mask if still.mask is not None else (1 << WORD_BITS) - 1
        return any(mask >> bit & 1 and (still.value >> bit & 1) == level for bit, level in self.blocking)


def _forced(bits: CommandBits) -> dict[int, int]:
    """The bit levels a command leaves whatever the last word was."""
    return {bit: bits.set >> bit & 1 for bit in range(WORD_BITS) if (bits.set | bits.clear) >> bit & 1}


def word_rule(commands: Mapping[Command, CommandBits]) -> WordRule:
    """Blocking bits: a stopping command forces them to the level opposite to the one ``enable_operation`` needs.
    Without ``enable_operation`` nothing is known to block."""
    reset = commands.get(Command.FAULT_RESET)
    fault_reset = 0 if reset is None else reset.set | (reset.edge or 0)
    enable = commands.get(Command.ENABLE_OPERATION)
    if enable is None:
        return WordRule((), fault_reset)
    needed = _forced(enable)
    blocking = {(bit, level) for command in STOPPING if command in commands
                for bit, level in _forced(commands[command]).items()
                if needed.get(bit, level) != level and not fault_reset >> bit & 1}
    return WordRule(tuple(sorted(blocking)), fault_reset)


CIA402_RULE = word_rule(cia402.COMMANDS)


def standard_motion(index: int, subindex: int) -> Motion | None:
    """The mark the standards give an object (None: writing it cannot move a drive by itself)."""
    if 0x6000 <= index < 0xA000:
        base = 0x6000 + (index - 0x6000) % CIA402_AXIS_SPAN
        if base == 0x60C1 and subindex == 0:  # the record's number of entries
            return None
        return CIA402_OBJECTS.get(base)
    return CIA301_OBJECTS.get(index)


def motion_of(item: Item) -> Motion | None:
    """The mark of an item: the standard's where it has one (its kind wins), else the profile's own."""
    return standard_motion(item.index, item.subindex) or item.entry.motion


def _section(profile: Profile | None) -> ControlSection | None:
    if profile is None or profile.control is None or profile.control.state_machine == "none":
        return None
    return profile.control


_RULES: dict[int, tuple[ControlSection, WordRule]] = {}


def rule_of(profile: Profile | None) -> WordRule:
    """How the control words of a node handled with ``profile`` are judged (its control section's commands)."""
    section = _section(profile)
    if section is None:
        return WordRule((), 0)
    cached = _RULES.get(id(section))
    if cached is None or cached[0] is not section:
        cached = _RULES[id(section)] = (section, word_rule(section.commands))
    return cached[1]


def counted(motion: Motion, rule: WordRule) -> list[StillValue]:
    """The still values of ``motion`` that count (see the module's text)."""
    if motion.kind == "control_word":
        return [still for still in motion.still if rule.sound(still)]
    if motion.kind == "setpoint":
        return [still for still in motion.still if still.value == 0 and still.mask is None]
    return [still for still in motion.still if still.mask is None]


def _matches(still: StillValue, raw: int) -> bool:
    return (raw & still.mask if still.mask is not None else raw) == still.value


def is_still(motion: Motion, raw: RawValue, rule: WordRule) -> bool:
    """True when writing ``raw`` cannot make the drive move (one of the mark's still values that count)."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return False
    values = counted(motion, rule)
    if isinstance(raw, float):  # a REAL32 setpoint: only an exact 0 with a still value 0
        return raw == 0 and motion.kind == "setpoint" and bool(values)
    if motion.kind == "control_word" and not rule.blocks(raw):
        return False
    return any(_matches(still, raw) for still in values)


@dataclass(frozen=True)
class Verdict:
    """What writing a value does: the mark (None: cannot move a drive) and whether the value is still."""

    motion: Motion | None
    still: bool

    @property
    def moving(self) -> bool:
        return self.motion is not None and not self.still

    @property
    def stopping(self) -> bool:
        """A control word that stops the drive: never refused, by a lease or for a confirmation."""
        return self.still and self.motion is not None and self.motion.kind == "control_word"


def judge(item: Item, raw: RawValue, profile: Profile | None) -> Verdict:
    """Whether writing ``raw`` to ``item`` (of a node handled with ``profile``) can make the drive move."""
    own = item.entry.motion
    standard = standard_motion(item.index, item.subindex)
    if standard is not None:
        still = is_still(standard, raw, CIA402_RULE) and (own is None or is_still(own, raw, CIA402_RULE))
        return Verdict(standard, still)
    if own is None:
        return Verdict(None, False)
    return Verdict(own, is_still(own, raw, rule_of(profile)))


def moves(item: Item, raw: RawValue, profile: Profile | None) -> Motion | None:
    """The mark when writing ``raw`` to ``item`` can make the drive move, else None."""
    verdict = judge(item, raw, profile)
    return verdict.motion if verdict.moving else None


def _entries(profile: Profile) -> list[tuple[str, Entry, int, int | None]]:
    objects = [(f"0x{o.index:04X}sub{o.subindex}", o, o.index, o.subindex) for o in profile.objects]
    return [*objects, *((p.ref, p, p.index or 0, p.subindex) for p in profile.parameters)]


def ignored_still_values(profile: Profile) -> list[tuple[str, str]]:
    """The profile's still values this module does not count: (ref, the value's meaning or its hex value)."""
    ignored: list[tuple[str, str]] = []
    for ref, entry, index, subindex in _entries(profile):
        if entry.motion is None:
            continue
        standard = standard_motion(index, subindex or 0) if index else None
        rule = CIA402_RULE if standard is not None else rule_of(profile)
        kept = counted(entry.motion, rule)
        if standard is not None and entry.motion.kind != standard.kind:
            kept = []
        ignored += [(ref, still.meaning or f"0x{still.value:04X}") for still in entry.motion.still if still not in kept]
    return ignored
