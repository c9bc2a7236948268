"""The 8400 motec EtherCAT manual's mailbox telegrams (chapter 9.2 and 11.3), as data.

The manual prints each telegram as a table of fields; the bytes here pack those fields little-endian (the manual's
byte order) with unused data bytes 0. Where the manual gives only one side of an exchange, the other side is
derived from the service tables of the same chapter and says so in ``notes``.
"""

from __future__ import annotations

from dataclasses import dataclass

MANUAL = "Lenze 8400 motec EtherCAT communication unit manual"


@dataclass(frozen=True)
class MailboxVector:
    id: str
    source: str
    telegram: bytes
    notes: str = ""


def _hex(text: str) -> bytes:
    return bytes.fromhex(text.replace("|", " "))


UPLOAD_C00039_1_RESPONSE = MailboxVector(
    "coe-upload-c00039.1-response", f"{MANUAL} §9.2 'Reading parameters', upload response of 0x5FD8 sub 1",
    _hex("0A 00 | 00 00 | 00 03 | 00 30 | 4B | D8 5F | 01 | A0 0F 00 00"),
    "C00039/1 Fixed_Setpoint_1, standard value 0x0FA0 (4000 = 40.00 % with the CANopen manual's factor 100)")
UPLOAD_C00039_1_REQUEST = MailboxVector(
    "coe-upload-c00039.1-request", f"{MANUAL} §9.2 'SDO Upload Request' table (derived)",
    _hex("0A 00 | 00 00 | 00 03 | 00 20 | 40 | D8 5F | 01 | 00 00 00 00"),
    "the manual prints only the response; the request follows the Upload Request table")
DOWNLOAD_1600_1_REQUEST = MailboxVector(
    "coe-download-1600.1-request", f"{MANUAL} §9.2 'Writing parameters', download request to 0x1600 sub 1",
    _hex("0A 00 | 00 00 | 00 03 | 00 20 | 23 | 00 16 | 01 | 10 01 93 5C"),
    "RxPDO 1 mapping entry 1 := 0x5C930110 (C00876/1, 16 bits)")
DOWNLOAD_1600_1_RESPONSE = MailboxVector(
    "coe-download-1600.1-response", f"{MANUAL} §9.2 'SDO Download Response' table (derived)",
    _hex("0A 00 | 00 00 | 00 03 | 00 30 | 60 | 00 16 | 01 | 00 00 00 00"))
EMERGENCY_OPERATIONAL_QUIT = MailboxVector(
    "coe-emergency-0x01bc8131", f"{MANUAL} §11.3 emergency of error 'Operational status quit [0x01bc8131]'",
    _hex("0A 00 | 00 00 | 00 03 | 00 10 | 00 10 01 00 31 81 BC 01"),
    "the manual gives the 8 EMCY bytes; mailbox length 0x0A and CoE service 1 (emergency) are ETG.1000.6's")
