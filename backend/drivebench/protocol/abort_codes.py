"""SDO abort codes: the CiA 301 table and the wording each manual uses for them.

``abort_text(code, vendor)`` answers the text a user sees next to an aborted read or write. The vendor tables
hold the manuals' own wording (Lenze) or the device's meaning of a code (MICROMASTER), keyed by profile
family.
"""

from __future__ import annotations

# CiA 301 V4.2, section 7.2.4.3.17 "Protocol SDO abort transfer", table 22.
CIA301: dict[int, str] = {
    0x05030000: "Toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "Client/server command specifier not valid or unknown",
    0x05040002: "Invalid block size (block mode only)",
    0x05040003: "Invalid sequence number (block mode only)",
    0x05040004: "CRC error (block mode only)",
    0x05040005: "Out of memory",
    0x06010000: "Unsupported access to an object",
    0x06010001: "Attempt to read a write only object",
    0x06010002: "Attempt to write a read only object",
    0x06020000: "Object does not exist in the object dictionary",
    0x06040041: "Object cannot be mapped to the PDO",
    0x06040042: "The number and length of the objects to be mapped would exceed PDO length",
    0x06040043: "General parameter incompatibility reason",
    0x06040047: "General internal incompatibility in the device",
    0x06060000: "Access failed due to a hardware error",
    0x06070010: "Data type does not match, length of service parameter does not match",
    0x06070012: "Data type does not match, length of service parameter too high",
    0x06070013: "Data type does not match, length of service parameter too low",
    0x06090011: "Sub-index does not exist",
    0x06090030: "Invalid value for parameter (download only)",
    0x06090031: "Value of parameter written too high (download only)",
    0x06090032: "Value of parameter written too low (download only)",
    0x06090036: "Maximum value is less than minimum value",
    0x060A0023: "Resource not available: SDO connection",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred or stored to the application",
    0x08000021: "Data cannot be transferred or stored to the application because of local control",
    0x08000022: "Data cannot be transferred or stored to the application because of the present device state",
    0x08000023: "Object dictionary dynamic generation fails or no object dictionary is present",
    0x08000024: "No data available",
}

# Lenze 8400 motec CANopen communication manual, ch. 9.2.4 (seed000 §6.5), verbatim.
LENZE_8400: dict[int, str] = {
    0x05030000: "Toggle bit not changed",
    0x05040000: "SDO protocol expired",
    0x05040001: "Invalid or unknown client/server command specifier",
    0x05040002: "Invalid block size (only block mode)",
    0x05040003: "Invalid sequence number (only block mode)",
    0x05040004: "CRC error (only block mode)",
    0x05040005: "Not sufficient memory",
    0x06010000: "Object access not supported",
    0x06010001: "Attempt to read a write-only object",
    0x06010002: "Attempt to write to a read-only object",
    0x06020000: "Object not listed in object directory",
    0x06040041: "Object not mapped to PDO",
    0x06040042: "Number and length of objects to be transferred longer than PDO length",
    0x06040043: "General parameter incompatibility",
    0x06040047: "General internal device incompatibility",
    0x06060000: "Access denied because of hardware error",
    0x06070010: "Unsuitable data type, unsuitable service parameter length",
    0x06070012: "Unsuitable data type, service parameter length exceeded",
    0x06070013: "Unsuitable data type, service parameter length not long enough",
    0x06090011: "Subindex does not exist",
    0x06090030: "Parameter value range exceeded",
    0x06090031: "Parameter values too high",
    0x06090032: "Parameter values too low",
    0x06090036: "Maximum value falls below minimum value",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred/saved for application",
    0x08000021: "Data cannot be transferred/saved for application due to local control",
    0x08000022: "Data cannot be transferred/saved for application due to current device status",
    0x08000023: "Dynamic generation of object directory failed or no object directory available",
}

# Lenze EMF2178IB communication manual, ch. 10.4 (seed001 §6.6), verbatim. The manual's texts for 0x06010001/2
# invert the meaning ("read writable object"); the CiA 301 meaning is added so the user is not misled.
LENZE_EMF2178IB: dict[int, str] = {
    0x05030000: "Toggle bit not changed",
    0x05040000: "SDO protocol expired",
    0x05040001: "Invalid or unknown client/server command specifier",
    0x05040002: "Invalid block size (only block mode)",
    0x05040003: "Invalid processing number (only block mode)",
    0x05040004: "CRC error (only block mode)",
    0x05040005: "Not enough memory",
    0x06010000: "Object access not supported",
    0x06010001: "Try to read writable object (CiA 301: attempt to read a write only object)",
    0x06010002: "Try to write readable object (CiA 301: attempt to write a read only object)",
    0x06020000: "Object not listed in object directory",
    0x06040041: "Object not mapped to PDO",
    0x06040042: "Number and length of objects to be transferred longer than PDO",
    0x06040043: "General parameter incompatibility",
    0x06040047: "General internal controller incompatibility",
    0x06060000: "Access denied because of hardware error",
    0x06070010: "Inappropriate data type, service parameter length",
    0x06070012: "Inappropriate data type, service parameter length exceeded",
    0x06070013: "Inappropriate data type, service parameters not long enough",
    0x06090011: "Subindex does not exist",
    0x06090030: "Parameter value range exceeded",
    0x06090031: "Parameter values too high",
    0x06090032: "Parameter values too low",
    0x06090036: "Maximum value falls below minimum value",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred or stored for the application",
    0x08000021: "Because of local control, data cannot be transferred or stored for the application",
    0x08000022: "Because of current controller status, data cannot be transferred or stored for the "
                "application",
    0x08000023: "Dynamic generation of object directory not successful or no object directory available",
}

# Lenze 8400 motec EtherCAT manual, ch. 9.5 (seed004 §7), verbatim. "Read access to a write-protected object"
# is the manual's wording for 0x06010001 (CiA 301: read of a write only object).
LENZE_8400_ETHERCAT: dict[int, str] = {
    0x00000000: "No error",
    0x05030000: "The status of the toggle bit has not changed",
    0x05040000: "SDO time-out protocol",
    0x05040001: "Invalid or unknown specification symbol for the client/server command",
    0x05040005: "Not enough space in the main memory",
    0x06010000: "Non-supported access to an object",
    0x06010001: "Read access to a write-protected object",
    0x06010002: "Write access to a write-protected object",
    0x06020000: "An object does not exist in the object directory",
    0x06040041: "An object cannot be mapped into the PDO",
    0x06040042: "The number and/or length of the objects mapped would exceed the PDO length",
    0x06040043: "General parameter incompatibility",
    0x06040047: "General internal incompatibility within the device",
    0x06060000: "Access has failed due to a fault in the hardware",
    0x06070010: "The data type or the parameter length does not correspond",
    0x06070012: "Incorrect data type (The parameter length is too large)",
    0x06070013: "Incorrect data type (The parameter length is too small)",
    0x06090011: "A subindex is not available",
    0x06090030: "The value range for parameters is too great (only for write access)",
    0x06090031: "The parameter value is too high",
    0x06090032: "The parameter value is too low",
    0x06090036: "The maximum value is lower than the minimum value",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred to the application or stored in the application",
    0x08000021: "Due to local control, data cannot be transferred to the application or stored in the "
                "application",
    0x08000022: "Due to the current device state, data cannot be transferred to the application or stored in "
                "the application",
    0x08000023: "The dynamic object directory generation has failed, or no object directory is available",
}

# MICROMASTER 420/430/440 CANopen option module, ch. 3.2.4 abort table (seed003 §5.1): the manual's name of
# the code and what it means on this device (most aborts are MM4 parameter-task errors recoded by the module).
SIEMENS_MM4: dict[int, str] = {
    0x05040000: "SDO protocol time overflow: the drive did not answer the option module's parameter task "
                "in time",
    0x06010001: "Illegal access: parameter is write-only (cannot be read)",
    0x06010002: "Illegal access: parameter is read-only (cannot be changed)",
    0x06020000: "Object not available in the object directory: parameter number does not exist",
    0x06040043: "General parameter incompatibility: illegal parameter value (only specific values permitted)",
    0x06070010: "Data type does not match the length of the SDO value: mixture of word and double word",
    0x06090011: "Subindex does not exist: parameter is not indexed or the index does not exist",
    0x06090030: "Parameter value exceeded: upper or lower limit exceeded",
    0x08000000: "General error: parameter task buffer busy (new task sent before the previous was answered)",
    0x08000020: "Data transfer error: data cannot be transferred to the application or saved",
    0x08000021: "Data not able to be transferred or saved due to local control: no change authorization "
                "(P0927)",
    0x08000022: "Service error: the drive does not permit the task in the present operating state",
}

VENDOR_TEXTS: dict[str, dict[int, str]] = {
    "lenze-8400": LENZE_8400,
    "lenze-8400-ethercat": LENZE_8400_ETHERCAT,
    "lenze-emf2178ib": LENZE_EMF2178IB,
    "siemens-mm4": SIEMENS_MM4,
}


def _vendor_table(vendor: str) -> dict[int, str]:
    """The table of profile family ``vendor``, or of the longest family it extends (``lenze-8400-motec``)."""
    key = vendor.lower()
    while key:
        if key in VENDOR_TEXTS:
            return VENDOR_TEXTS[key]
        key = key.rpartition("-")[0]
    return {}


def abort_text(code: int, vendor: str | None = None) -> str:
    """The text for abort ``code``: the vendor manual's wording if it has one, else CiA 301's."""
    if vendor:
        text = _vendor_table(vendor).get(code)
        if text:
            return text
    return CIA301.get(code, f"Unknown abort code 0x{code:08X}")
