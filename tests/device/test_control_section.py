"""The ``control`` and ``commissioning`` profile sections: validated, published in the profile schema, carried by
the seed profiles; a CiA 402 device without one gets the standard section, with standard names only."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from drivebench.config import REPO_ROOT
from drivebench.device.drive import cia402
from drivebench.device.drive.control import ControlSection, Sequence
from drivebench.device.profiles.loader import ProfileRegistry, load_profile_file
from drivebench.services.control.drive_words import family_of_profile

SEEDS = {"siemens-micromaster4-canopen": ("cia402", ["mm-velocity", "mm-torque", "mm-quick"]),
         "lenze-8200-vector-emf2178ib": ("emf2178ib", ["emf-8200"]),
         "lenze-93xx-emf2178ib": ("emf2178ib-aif", ["emf-93xx"]),
         "lenze-8400-motec-canopen": ("lenze8400", ["l8400"])}
VENDOR_WORDS = ("MICROMASTER", "Lenze", "8400", "8200", "P0700", "EMF2178IB", "AIF", "RFG", "OFF1", "CINH")


def test_the_schema_publishes_both_sections() -> None:
    schema = ProfileRegistry.json_schema()
    assert {"control", "commissioning"} <= set(schema["properties"])
    assert {"ControlSection", "Sequence", "Step", "CommandBits"} <= set(schema["$defs"])


@pytest.mark.parametrize("profile_id", sorted(SEEDS))
def test_seed_profiles_carry_their_control_and_sequences(registry: ProfileRegistry, profile_id: str) -> None:
    profile = registry.get(profile_id)
    key, sequences = SEEDS[profile_id]
    assert profile.control is not None and profile.control.key == key
    assert [seq.key for seq in profile.commissioning] == sequences
    assert profile.control.simulation is not None


def test_a_cia402_profile_without_a_section_gets_the_standard_one_only() -> None:
    upload = (REPO_ROOT / "tests" / "data" / "eds" / "linear_axis_cia402.eds").read_bytes()
    profile = load_profile_file(upload, "linear_axis_cia402.eds")
    family = family_of_profile(profile)
    assert profile.control is None and family is not None and family.generic
    section = family.section.model_dump_json()
    assert [word for word in VENDOR_WORDS if word.lower() in section.lower()] == []
    assert family.section.modes == {1: "Profile position", 3: "Profile velocity", 4: "Profile torque", 6: "Homing",
                                    8: "Cyclic synchronous position", 9: "Cyclic synchronous velocity",
                                    10: "Cyclic synchronous torque"}
    assert family.state_of(0x0237) == "operation_enabled" and family.state_of(0x0250) == "switch_on_disabled"


def test_names_of_modes_methods_errors_and_units() -> None:
    assert cia402.mode_label(-59) == "manufacturer-specific (\u221259)" and cia402.mode_label(6) == "Homing"
    assert cia402.modes_from_6502(0x3AD) == [1, 3, 4, 6, 8, 9, 10]
    assert cia402.homing_label(34) == "Index pulse in positive direction"
    assert cia402.error_text(0x8611) == "Following error" and cia402.error_text(0xFF42).startswith("Manufacturer")
    assert cia402.error_text(0x3333) == "Voltage (0x3333)"
    assert [cia402.si_unit(code) for code in (0x00410000, 0x00B44700, 0xFD010000, 0xFD010300, 0x12345678)] == [
        "°", "rpm", "mm", "mm/s", None]


def test_bad_sections_are_refused_in_words() -> None:
    with pytest.raises(ValidationError, match="state_machine"):
        ControlSection.model_validate({"key": "x", "state_machine": "vendor-magic", "title": "t",
                                       "control_word": "0x6040", "status_word": "0x6041"})
    with pytest.raises(ValidationError, match="kind"):
        Sequence.model_validate({"key": "s", "title": "t", "source": "m", "steps": [{"title": "x", "kind": "poke"}]})


def test_sequence_steps_round_trip_as_telegram_data(registry: ProfileRegistry) -> None:
    sequence = registry.get("siemens-micromaster4-canopen").commissioning[0]
    first = sequence.steps[0]
    assert (first.kind, first.index, first.sub, first.data, first.printed) == (
        "sdo", 0x27F8, 0, b"\0\0", "2b f8 27 00 00 00 00 00")
    again = Sequence.model_validate(json.loads(sequence.model_dump_json()))
    assert again == sequence


def test_a_transition_to_a_state_the_section_lacks_is_refused() -> None:
    with pytest.raises(ValidationError, match="arrow 1: 'nowhere'"):
        ControlSection.model_validate({"key": "x", "state_machine": "cia402", "title": "t", "control_word": "0x6040",
                                       "status_word": "0x6041", "states": [{"key": "ready", "label": "Ready",
                                                                            "col": 0, "row": 0}],
                                       "arrows": [{"from_state": "ready", "to_state": "nowhere"}]})
