"""The profile's behaviour sections (commands, sdo_channels, abort_texts, pdo_rules) and its family key: what a
file may say, and the error in words where it says something wrong."""

from __future__ import annotations

import json
from typing import Any

import pytest
from pydantic import ValidationError

from drivebench.device.profiles import pdo_notes
from drivebench.device.profiles.pdo_rules import PdoRules
from drivebench.device.profiles.profile import Profile

MINIMAL: dict[str, Any] = {"id": "acme-servo", "family": "acme-servo",
                           "identity": {"vendor_name": "Acme", "product_name": "Acme servo"}}


def profile(**sections: Any) -> Profile:
    return Profile.model_validate({**MINIMAL, **sections})


def test_a_new_family_described_only_by_data() -> None:
    acme = profile(
        commands={"save": {"ref": "0x2000.1", "value": "save", "done": "Node {node} stored."}},
        sdo_channels=[{"number": 2, "rx_base": "0x6C0", "tx_base": "0x5C0", "max_node_id": 31}],
        abort_texts={"source": "Acme manual 4.2", "texts": {"0x06090030": "Value out of range (Acme)"}},
        pdo_rules={"device_notes": ["Acme: 2 PDOs."],
                   "pdos": [{"direction": "tpdo", "number": 1, "static_mapping": ["0x6041"],
                             "static_mapping_note": "count 0 sends the status word"}],
                   "transmission": [{"types": [[241, 251]], "note": "reserved"}]})
    assert acme.commands is not None and acme.commands.save is not None
    assert (acme.commands.save.raw, acme.commands.save.via) == (int.from_bytes(b"save", "little"), "0x2000.1 = 'save'")
    assert acme.sdo_channels[0].cob_ids(5) == (0x6C5, 0x5C5) and acme.sdo_channels[0].parameter_index == 0x1201
    assert acme.abort_texts is not None and acme.abort_texts.texts[0x06090030] == "Value out of range (Acme)"
    assert pdo_notes.device_notes(acme) == ["Acme: 2 PDOs."]
    assert pdo_notes.static_mapping(acme, "tpdo", 1) == ["0x6041"]
    assert pdo_notes.transmission_note(acme, "rpdo", 245) == "reserved"
    assert pdo_notes.transmission_note(acme, "rpdo", 254) is None
    dumped = json.loads(acme.model_dump_json(exclude_none=True))
    assert dumped["abort_texts"]["texts"] == {"0x06090030": "Value out of range (Acme)"}
    assert Profile.model_validate(dumped) == acme  # a file round-trips


@pytest.mark.parametrize(("sections", "words"), [
    ({"family": "Acme Servo"}, "family"),
    ({"commands": {"save": {"ref": "0x1010.1", "value": "save"}}}, "done"),
    ({"sdo_channels": [{"rx_base": "0x900", "tx_base": "0x5C0"}]}, "rx_base"),
    ({"abort_texts": {"texts": {"abort": "x"}}}, "abort_texts"),
    ({"pdo_rules": {"transmission": [{"types": [], "note": "x"}]}}, "types"),
    ({"pdo_rules": {"pdos": [{"direction": "both", "number": 1}]}}, "direction"),
    ({"pdo_rules": {"colour": "red"}}, "colour"),
])
def test_a_wrong_section_is_refused_naming_the_field(sections: dict[str, Any], words: str) -> None:
    with pytest.raises(ValidationError, match=words):
        profile(**sections)


def test_mapping_bits_texts_must_format() -> None:
    rule = {"direction": "rpdo", "objects": [], "pdos": [], "order_text": "x", "byte_text": "{ref} = {value}",
            "no_bit_text": "{ref}"}
    with pytest.raises(ValidationError, match="value"):
        PdoRules.model_validate({"mapping_bits": [rule]})

