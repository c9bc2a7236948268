"""CANopen frame decoding: services and nodes by COB-ID, texts in words, SDO context across segments/blocks."""

from __future__ import annotations

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen.decode import SdoTracker, Service, classify, decode_frame
from tests.vectors.manual_sdo import LENZE_8400


def frame(cob_id: int, hex_data: str = "", **kwargs: object) -> can.Message:
    return can.Message(arbitration_id=cob_id, data=bytes.fromhex(hex_data),
                       is_extended_id=bool(kwargs.pop("extended", False)), **kwargs)  # type: ignore[arg-type]


def names(node: int, index: int, sub: int) -> str | None:
    return {(0x5FC2, 0): "C00061 Heatsink temperature", (0x1008, 0): "Manufacturer device name"}.get((index, sub))


@pytest.mark.parametrize(("cob_id", "service", "node"), [
    (0x000, Service.NMT, None), (0x080, Service.SYNC, None), (0x081, Service.EMCY, 1), (0x0FF, Service.EMCY, 127),
    (0x100, Service.TIME, None), (0x185, Service.TPDO1, 5), (0x205, Service.RPDO1, 5), (0x285, Service.TPDO2, 5),
    (0x305, Service.RPDO2, 5), (0x385, Service.TPDO3, 5), (0x405, Service.RPDO3, 5), (0x485, Service.TPDO4, 5),
    (0x505, Service.RPDO4, 5), (0x585, Service.SDO_TX, 5), (0x605, Service.SDO_RX, 5),
    (0x705, Service.HEARTBEAT, 5), (0x7E4, Service.LSS, None), (0x7E5, Service.LSS, None),
    (0x700, Service.UNKNOWN, None), (0x680, Service.UNKNOWN, None), (0x7FF, Service.UNKNOWN, None),
])
def test_classify_predefined_connection_set(cob_id: int, service: Service, node: int | None) -> None:
    assert classify(cob_id) == (service, node)


def test_29_bit_ids_are_unknown() -> None:
    assert classify(0x185, is_extended=True) == (Service.UNKNOWN, None)


@pytest.mark.parametrize(("msg", "text"), [
    (frame(0x605, "40C25F0000000000"), "0x605 SDO rx node 5: read 0x5FC2sub0 (C00061 Heatsink temperature)"),
    (frame(0x585, "4BC25F002B000000"),
     "0x585 SDO tx node 5: read response 0x5FC2sub0 (C00061 Heatsink temperature) = 43 (0x002B)"),
    (frame(0x605, "2B17100064000000"), "0x605 SDO rx node 5: write 0x1017sub0 = 100"),
    (frame(0x585, "6017100000000000"), "0x585 SDO tx node 5: write response 0x1017sub0 OK"),
    (frame(0x605, "211710000B000000"), "0x605 SDO rx node 5: write 0x1017sub0, segmented, 11 bytes"),
    (frame(0x585, "3000000000000000"), "0x585 SDO tx node 5: download segment response toggle 1"),
    (frame(0x585, "C2C25F0010000000"),
     "0x585 SDO tx node 5: block read response 0x5FC2sub0 (C00061 Heatsink temperature), 16 bytes"),
    (frame(0x585, "D912340000000000"), "0x585 SDO tx node 5: block upload end, 6 unused bytes, CRC 0x3412"),
    (frame(0x000, "0105"), "0x000 NMT node 5: Start remote node 5"),
    (frame(0x000, "8100"), "0x000 NMT: Reset node: all nodes"),
    (frame(0x000, "800C"), "0x000 NMT node 12: Enter pre-operational: node 12"),
    (frame(0x705, "05"), "0x705 Heartbeat node 5: Operational"),
    (frame(0x705, "7F"), "0x705 Heartbeat node 5: Pre-operational"),
    (frame(0x705, "04"), "0x705 Heartbeat node 5: Stopped"),
    (frame(0x705, "00"), "0x705 Heartbeat node 5: Boot-up"),
    (frame(0x705, "85"), "0x705 Heartbeat node 5: Operational, toggle 1"),
    (frame(0x705, is_remote_frame=True, dlc=1), "0x705 Heartbeat node 5: node guarding request"),
    (frame(0x080), "0x080 SYNC"),
    (frame(0x080, "07"), "0x080 SYNC: counter 7"),
    (frame(0x185, "0102"), "0x185 TPDO1 node 5: 2 bytes 01 02"),
    (frame(0x7E5, "5E00000000000000"), "0x7E5 LSS: request: inquire node-ID"),
    (frame(0x18FF0001, "010203", extended=True), "0x18FF0001 Unknown: 3 bytes 01 02 03"),
    (frame(0x085, "0000000000000000"), "0x085 EMCY node 5: error reset, register 0x00"),
])
def test_texts_in_words(msg: can.Message, text: str) -> None:
    assert decode_frame(msg, names=names).text == text


def test_emcy_uses_the_profile_text_and_register_bits() -> None:
    msg = frame(0x085, "1032110000000000")
    plain = decode_frame(msg).summary
    assert plain.startswith("0x3210 ") and "register 0x11 (Generic error, Communication error)" in plain
    vendor = decode_frame(msg, emcy_texts=lambda node, code, data: "DC bus overvoltage" if code == 0x3210 else None)
    assert vendor.summary.startswith("0x3210 DC bus overvoltage, register 0x11")


def test_abort_in_the_vendors_words(registry: ProfileRegistry) -> None:
    msg = frame(0x585, "80C25F0000000206")
    text = decode_frame(msg, names=names).text
    assert text.startswith("0x585 SDO tx node 5: abort 0x06020000 Object does not exist in the object dictionary")
    assert text.endswith("0x5FC2sub0 (C00061 Heatsink temperature)")
    texts = registry.get("lenze-8400-motec-canopen").abort_texts
    assert texts is not None  # the profile's abort_texts section: the manual's wording
    worded = decode_frame(msg, names=names, abort_texts=lambda node: texts.texts if node == 5 else None).text
    assert "abort 0x06020000 Object not listed in object directory, 0x5FC2sub0" in worded


def test_error_frame_classes_in_words() -> None:
    msg = can.Message(is_error_frame=True, arbitration_id=0x040 | 0x004, data=bytes(8))
    decoded = decode_frame(msg)
    assert decoded.service is Service.ERROR_FRAME
    assert decoded.summary.startswith("controller problem, bus off (class 0x044)")


def test_time_of_day() -> None:
    # 12:00:00.000 on day 14610 after 1984-01-01 (= 2024-01-01).
    data = (12 * 3600 * 1000).to_bytes(4, "little") + (14610).to_bytes(2, "little")
    assert decode_frame(frame(0x100, data.hex())).summary == "2024-01-01 12:00:00.000"


def test_segmented_upload_carries_the_object_through_the_segments() -> None:
    """The manual's C00099 example (8400 motec ch. 9.3.3, node 12): initiate 0x41 with size 11, segments with
    toggles 0x60/0x70, last segment 0x17; the segments name the object although they do not carry it."""
    vector = next(v for v in LENZE_8400 if v.id == "8400-tv7-read-c00099")
    frames = [can.Message(arbitration_id=f.cob_id, data=f.data, is_extended_id=False)
              for pair in vector.exchanges for f in pair]
    c00099 = {(0x5F9C, 0): "C00099 Firmware version"}
    tracker = SdoTracker()
    texts = [decode_frame(m, names=lambda n, i, s: c00099.get((i, s)), sdo_context=tracker.observe(m)).summary
             for m in frames]
    assert texts[0] == "read 0x5F9Csub0 (C00099 Firmware version)"
    assert texts[1] == "read response 0x5F9Csub0 (C00099 Firmware version), segmented, 11 bytes"
    assert texts[2] == "upload segment request 0x5F9Csub0 (C00099 Firmware version) toggle 0"
    assert texts[3] == ("upload segment 0x5F9Csub0 (C00099 Firmware version) toggle 0, 7 bytes: "
                        "30 31 2E 30 30 2E 30 '01.00.0'")
    assert texts[4] == "upload segment request 0x5F9Csub0 (C00099 Firmware version) toggle 1"
    assert texts[5] == "upload segment 0x5F9Csub0 (C00099 Firmware version) toggle 1, 4 bytes, last: 30 2E 30 30 '0.00'"


def test_block_download_segments_are_not_read_as_commands() -> None:
    tracker = SdoTracker()
    frames = [frame(0x605, "C6C25F0010000000"), frame(0x585, "A4C25F0004000000"),
              frame(0x605, "0141424344454647"), frame(0x605, "0248494A4B4C4D4E"),
              frame(0x605, "834F505100000000"), frame(0x585, "A203040000000000"),
              frame(0x605, "D912340000000000"), frame(0x585, "A100000000000000")]
    texts = [decode_frame(m, names=names, sdo_context=tracker.observe(m)).summary for m in frames]
    assert texts[0] == "block write 0x5FC2sub0 (C00061 Heatsink temperature), 16 bytes"
    assert texts[2].startswith("block segment 1 0x5FC2sub0")
    assert texts[4].startswith("block segment 3, last 0x5FC2sub0")
    assert texts[5] == "block ack seqno 3, blksize 4"
    assert texts[6] == "block download end, 6 unused bytes, CRC 0x3412"
    assert texts[7] == "block download end confirmed"
