"""The ``faults`` profile section (device/drive/faults.py): entries need their source, numbers are read where the
section says and matched on the bits it names."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from drivebench.device.drive.faults import FaultsSection, decode_emcy


def test_an_entry_without_its_source_is_refused() -> None:
    with pytest.raises(ValidationError, match="source"):
        FaultsSection.model_validate({"entries": [{"number": 1, "text": "Overcurrent"}]})


def test_the_number_is_read_where_the_section_says_and_matched_on_its_mask() -> None:
    section = FaultsSection.model_validate({
        "emcy_number": {"codes": ["0xF000"], "byte": 4, "length": 4}, "match_mask": "0x03FFFFFF",
        "entries": [{"number": "0x11C4000B", "name": "OC1", "text": "Short circuit", "source": "manual p. 76"}]})
    frame_bytes_3_to_7 = b"\x00" + (0x05C4000B).to_bytes(4, "little")
    decoded = decode_emcy(section, 0xF000, frame_bytes_3_to_7)
    assert decoded is not None and decoded.label == "OC1" and decoded.text == "Short circuit"
    assert decode_emcy(section, 0x8130, frame_bytes_3_to_7) is None, "only the codes that carry the number"
    assert decode_emcy(section, 0xF000, bytes(5)) is None, "0: no fault number"
    assert decode_emcy(None, 0xF000, frame_bytes_3_to_7) is None
