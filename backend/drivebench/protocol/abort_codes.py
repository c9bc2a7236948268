"""SDO abort codes: the CiA 301 table, and the device manual's wording where a profile has one.

``abort_text(code, texts)`` answers the text a user sees next to an aborted read or write; ``texts`` is the
profile's ``abort_texts`` section (the manual's own wording, or the device's meaning of a code), kept as the manual
prints it. CiA 301's texts are English :class:`~drivebench.i18n.Text` put into the reader's language where shown.
"""

from __future__ import annotations

from collections.abc import Mapping

from drivebench.i18n import N_, Text

# CiA 301 V4.2, section 7.2.4.3.17 "Protocol SDO abort transfer", table 22.
CIA301: dict[int, str] = {
    0x05030000: N_("Toggle bit not alternated"),
    0x05040000: N_("SDO protocol timed out"),
    0x05040001: N_("Client/server command specifier not valid or unknown"),
    0x05040002: N_("Invalid block size (block mode only)"),
    0x05040003: N_("Invalid sequence number (block mode only)"),
    0x05040004: N_("CRC error (block mode only)"),
    0x05040005: N_("Out of memory"),
    0x06010000: N_("Unsupported access to an object"),
    0x06010001: N_("Attempt to read a write only object"),
    0x06010002: N_("Attempt to write a read only object"),
    0x06020000: N_("Object does not exist in the object dictionary"),
    0x06040041: N_("Object cannot be mapped to the PDO"),
    0x06040042: N_("The number and length of the objects to be mapped would exceed PDO length"),
    0x06040043: N_("General parameter incompatibility reason"),
    0x06040047: N_("General internal incompatibility in the device"),
    0x06060000: N_("Access failed due to a hardware error"),
    0x06070010: N_("Data type does not match, length of service parameter does not match"),
    0x06070012: N_("Data type does not match, length of service parameter too high"),
    0x06070013: N_("Data type does not match, length of service parameter too low"),
    0x06090011: N_("Sub-index does not exist"),
    0x06090030: N_("Invalid value for parameter (download only)"),
    0x06090031: N_("Value of parameter written too high (download only)"),
    0x06090032: N_("Value of parameter written too low (download only)"),
    0x06090036: N_("Maximum value is less than minimum value"),
    0x060A0023: N_("Resource not available: SDO connection"),
    0x08000000: N_("General error"),
    0x08000020: N_("Data cannot be transferred or stored to the application"),
    0x08000021: N_("Data cannot be transferred or stored to the application because of local control"),
    0x08000022: N_("Data cannot be transferred or stored to the application because of the present device state"),
    0x08000023: N_("Object dictionary dynamic generation fails or no object dictionary is present"),
    0x08000024: N_("No data available"),
}

UNKNOWN = N_("Unknown abort code {code}")


def abort_text(code: int, texts: Mapping[int, str] | None = None) -> str:
    """The text for abort ``code``: the device manual's wording where its profile has one (``texts``, the
    profile's ``abort_texts``), else CiA 301's (translated where shown)."""
    if texts:
        text = texts.get(code)
        if text:
            return text
    return Text(CIA301[code]) if code in CIA301 else Text(UNKNOWN, code=f"0x{code:08X}")
