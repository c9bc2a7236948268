"""The still-value rule (issue 27 items 2 and 4) over every seed profile: each control word the rule passes unasked
cannot enable the drive from any state, judged by a small model of each state machine written here from the manuals
(not from the rule or the profiles' commands), and every stopping command the control section has still passes.

The models (which held word can bring the drive into a state where the motor turns, whatever the state before):
* CiA 402 (CiA 402-2 state machine; MICROMASTER manual §4 and the generic servo): "operation enabled" is entered only
  by "enable operation" (bits 0...3 = 1111, bit 7 = 0) from "switched on" or "quick stop active"; a fault reset
  (bit 7 edge) leaves "fault".
* 8400 device control (CiA 402-like, Lenze bits): SwitchOn (0) and EnableOperation (3) set, SetQuickStop (2) and
  SetCInh (8) cleared; SetFail (14) raises a fault that ResetFault (7, edge) clears, after which the same word acts.
* EMF2178IB AIF control word (ch. 9.3.1): enabled while QSP (3) and CINH (9) are cleared; TRIP-SET (10) raises a
  fault that TRIP-RESET (11, edge) clears, after which the same word acts.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from drivebench.device.drive import cia402
from drivebench.device.drive.control import Command
from drivebench.device.drive.motion import ignored_still_values, is_still, judge, rule_of, word_rule
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.profile import Motion, Profile, StillValue

PROFILES = sorted((Path(__file__).parents[2] / "device_profiles").glob("*.json"))


def _cia402(word: int) -> bool:
    return word & 0x8F == 0x0F or bool(word & 0x80)


def _lenze8400(word: int) -> bool:
    return word & 0x010D == 0x0009 or bool(word & 0x0080)


def _emf2178ib(word: int) -> bool:
    return word & 0x0208 == 0 or bool(word & 0x0800)


MODELS: dict[str, Callable[[int], bool]] = {"cia402": _cia402, "lenze8400": _lenze8400,
                                            "emf2178ib": _emf2178ib, "emf2178ib-aif": _emf2178ib}
"""Control section key -> can the held word enable (or, by a fault reset, restart) the drive from some state."""


def _profile(path: Path) -> Profile:
    return Profile.model_validate_json(path.read_text())


def _named(stem: str) -> Profile:
    return _profile(next(path for path in PROFILES if path.stem == stem))


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.stem)
def test_every_still_mark_of_a_seed_profile_counts(path: Path) -> None:
    assert ignored_still_values(_profile(path)) == []


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.stem)
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_no_still_control_word_of_a_seed_profile_can_enable_from_any_state(path: Path) -> None:
    profile = _profile(path)
    catalog = Catalog(profile)
    words = [item for item in catalog.items if (verdict := judge(item, 0, profile)).motion is not None
             and verdict.motion.kind == "control_word"]
    if not words:
        return
    section = profile.control
    assert section is not None or cia402.has_drive_words(profile), f"{path.stem}: control words, no control section"
    can_enable = MODELS[section.key if section is not None else "cia402"]
    for item in words:
        passed = [word for word in range(0x10000) if judge(item, word, profile).still]
        assert passed, f"{item.ref}: no stop word passes"
        enabling = [f"0x{word:04X}" for word in passed if can_enable(word)]
        assert not enabling, f"{path.stem} {item.ref}: still words that can enable: {enabling[:8]}"


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.stem)
def test_the_stopping_commands_pass_unasked(path: Path) -> None:
    """Quick stop, disable operation, shutdown and disable voltage from an enabled word are still."""
    profile = _profile(path)
    section = profile.control
    if section is None or Command.ENABLE_OPERATION not in section.commands:
        return
    item = Catalog(profile).resolve(section.control_word)
    enable = section.commands[Command.ENABLE_OPERATION]
    enabled = enable.set
    for command in (Command.QUICK_STOP, Command.DISABLE_OPERATION, Command.SHUTDOWN, Command.DISABLE_VOLTAGE):
        bits = section.commands.get(command)
        if bits is None:
            continue
        word = (enabled & ~bits.clear & 0xFFFF) | bits.set
        assert judge(item, word, profile).stopping, f"{path.stem}: {command} 0x{word:04X} would be asked"
    reset = section.commands[Command.FAULT_RESET]
    assert judge(item, (enabled | reset.set) & ~reset.clear, profile).moving, "a fault reset is never still"


def test_the_blocking_bits_come_from_the_commands() -> None:
    lenze = word_rule(_named("lenze-8400-motec-canopen").control.commands)  # type: ignore[union-attr]
    assert lenze.blocking == ((0, 0), (2, 1), (3, 0), (8, 1)) and lenze.fault_reset == 0x0080
    emf = word_rule(_named("lenze-8200-vector-emf2178ib").control.commands)  # type: ignore[union-attr]
    assert emf.blocking == ((3, 1), (9, 1)) and emf.fault_reset == 0x0800


def test_a_mark_the_rule_cannot_judge_passes_nothing() -> None:
    """A control word in a profile without a control section, and masks that hold no blocking bit."""
    anything = Motion(kind="control_word", still=[StillValue(value=0, mask=0)])
    assert not is_still(anything, 0x0000, rule_of(None))
    lenze = rule_of(_named("lenze-8400-motec-canopen"))
    assert not is_still(Motion(kind="control_word", still=[StillValue(value=0x4000, mask=0x4000)]), 0x4009, lenze)
    assert is_still(Motion(kind="control_word", still=[StillValue(value=0x0100, mask=0x0100)]), 0x4109, lenze)
    assert not is_still(Motion(kind="setpoint", still=[StillValue(value=0, mask=0)]), 5000, lenze)
