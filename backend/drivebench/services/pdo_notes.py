"""What the manuals say about a device's PDOs beyond CiA 301: permitted transmission types, fixed mappings,
mapping order rules, Lenze ports and identifiers, MICROMASTER P2041. Texts for the PDO tab and checks for
:func:`drivebench.services.pdo.check_mapping`.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

from drivebench.device.profile import Profile

LENZE_8400 = "lenze-8400"
EMF2178IB = "lenze-emf2178ib"
MM4 = "siemens-mm4"

# MICROMASTER ch. 5.4: the internal parameters keep one bit per mappable object (P2041.02/.03), so a mapping must
# list its objects in this order (lowest mapping sequence first). (index, sub) -> (sequence, P2041 bit).
MM4_RPDO_ORDER: dict[tuple[int, int], tuple[int, int]] = {
    (0x6040, 0): (1, 0), (0x6042, 0): (2, 1), (0x6052, 0): (2, 1), (0x2802, 3): (3, 2), (0x2802, 4): (4, 3),
    (0x6071, 0): (5, 4), (0x2802, 6): (6, 5), (0x6060, 0): (7, 6)}
MM4_TPDO_ORDER: dict[tuple[int, int], tuple[int, int]] = {
    (0x6041, 0): (1, 8), (0x6043, 0): (2, 9), (0x6053, 0): (2, 9), (0x2803, 3): (3, 10), (0x2803, 4): (4, 11),
    (0x6077, 0): (5, 12), (0x6044, 0): (6, 13), (0x6054, 0): (6, 13), (0x6061, 0): (7, 14)}
MM4_PER_UNIT = {0x6052, 0x6053, 0x6054}
# MICROMASTER ch. 5.6 table 5-1: where P2041 keeps each PDO's transmission type. The RPDO bits' text is garbled and
# contradictory; the manual's trace (0xFF written to 0x1400/1404/1405.2 -> P2041.01 = 0x00FF) supports 0 = async.
MM4_TYPE_PLACE: dict[tuple[str, int], tuple[str, str]] = {
    ("tpdo", 1): ("P2041.00", "low byte"), ("tpdo", 5): ("P2041.00", "high byte"),
    ("tpdo", 6): ("P2041.01", "low byte"),
    ("rpdo", 1): ("P2041.01", "bit 8"), ("rpdo", 5): ("P2041.01", "bit 9"), ("rpdo", 6): ("P2041.01", "bit 10")}


def _lenze_port(direction: str, number: int) -> str:
    return f"CAN{number}_{'IN' if direction == 'rpdo' else 'OUT'}"


def device_notes(profile: Profile) -> list[str]:
    """Notes for the whole PDO tab of a device."""
    family = profile.family
    if family == LENZE_8400:
        return [
            "8400 motec: 2 RPDOs (port blocks CAN1_IN, CAN2_IN) and 2 TPDOs (CAN1_OUT, CAN2_OUT), 4 words each "
            "(manual ch. 8.1). The port interconnection is made in the »Engineer«; with C00007 = 40 the "
            "preconfigured interconnection is active.",
            "Identifiers (ch. 8.3, C00353): CANopen base IDs (Lenze setting) or Lenze base IDs. They differ only in "
            "RPDO2: Lenze base 0x281 instead of 0x300 - then RPDO2 of node n (0x281 + n) has the COB-ID of "
            "TPDO2 of node n + 1 (0x280 + n + 1): two nodes at adjacent addresses collide.",
            "Mapping (I-1600/1601, I-1A00/1A01): IEC 61131 process data words are mapped, only whole bytes; "
            "the manual says the 4th mapping entry is used for the static mapping.",
            "Transmission types 252/253 (RTR) and 255 are not permissible (ch. 8.4); 254 = event-controlled "
            "and cyclic with the event timer.",
        ]
    if family == EMF2178IB:
        return [
            "EMF2178IB: PDOs carry the AIF process data of the basic device: AIF-IN words C1822 (0x58E1) / "
            "double words C1824 (0x58DF) for RPDOs, AIF-OUT C1823 (0x58E0) / C1825 (0x58DE) for TPDOs "
            "(manual ch. 9.3.2). The module does not check the mapping against the AIF mode: the picker offers "
            "the words the basic device uses.",
            "Mapping is not possible with old devices of the 8200 series. I-1401/1402 (PDO2/3) are not available "
            "with 8200 vector and 93XX controllers.",
        ]
    if family == MM4:
        return [
            "MICROMASTER: PDO1 (RPDO1 control word, TPDO1 status word) has a fixed mapping; PDO5 and PDO6 are "
            "mapped via CANopen (sub 0 := 0, entries, sub 0 := count) or with P2041.02/.03 (manual ch. 5.4, 5.6).",
            "Objects must be mapped in the manual's mapping sequence (lowest first), because P2041 keeps one bit "
            "per object: e.g. free object 2802.03 before the torque setpoint 6071. A wrong order is refused "
            "with an EMCY and the mapping is not used.",
            "RPDOs only distinguish synchronous (0) and asynchronous (255): P2041.01 bits 8-10 store one bit; "
            "after power-on the type reads 0 or 255. Do not save the transmission types with 0x1010.",
            "Process data are updated about every 8 ms: send setpoints no faster than that.",
        ]
    return []


def static_mapping(profile: Profile, direction: str, number: int) -> list[str]:
    """What a PDO carries while its mapping count is 0, as codes; empty where count 0 means nothing is mapped.

    8400 motec: the manual prints 0 as the default of I-1600/1601/1A00/1A01 sub 0...4 (so the device holds count 0)
    and exchanges 4 words per port (ch. 8.1: CAN1_IN/CAN2_IN, CAN1_OUT/CAN2_OUT), "the 4th mapping entry is used
    for the static mapping". CiA 301 would read count 0 as "PDO not used"; on the 8400 motec count 0 is the
    static mapping of the port's 4 words: C00866/1...4 (RPDO1), /5...8 (RPDO2), C00868 likewise for the TPDOs.
    """
    if profile.family != LENZE_8400 or number not in (1, 2):
        return []
    code = "C00866" if direction == "rpdo" else "C00868"
    return [f"{code}/{4 * (number - 1) + word}" for word in range(1, 5)]


def static_mapping_note(direction: str, number: int) -> str:
    port = _lenze_port(direction, number)
    meaning = "the words' meaning follows the port interconnection (»Engineer«)"
    if (direction, number) == ("rpdo", 1):
        meaning = ("word 1 = control word (C00409/1 'LP_CanIn1_wIn1(wCtrl)'), the others follow the port "
                   "interconnection (C00007 = 40: preconfigured; simulator: word 2 = speed setpoint)")
    elif (direction, number) == ("tpdo", 1):
        meaning = ("the words follow the port interconnection (C00007 = 40: preconfigured; simulator: word 1 = status "
                   "word, word 2 = actual speed)")
    return (f"Static mapping (Lenze setting): count 0, no entries (the manual's default), yet the PDO carries the 4 "
            f"words of port {port} (ch. 8.1); {meaning}. Mapping objects replaces it; count 0 restores it.")


def pdo_notes(profile: Profile, direction: str, number: int) -> list[str]:
    """Notes for one PDO (its port, its monitoring, its fixed mapping, its P2041 bits)."""
    family = profile.family
    if family == LENZE_8400:
        port = _lenze_port(direction, number)
        notes = [f"Port {port}."]
        if direction == "rpdo":
            notes.append(f"Monitoring: C00357/{number} ({port} monitoring time, 3000 ms Lenze setting, 0 = off); "
                         f"when exceeded the response C00593/{number} applies (0 No reaction, 1 Fault, "
                         f"2 Trouble, 4 WarningLocked).")
            if number == 2:
                notes.append("Lenze base ID (C00353/2 = 0): 0x281 + node id - the TPDO2 COB-ID of the next node.")
        else:
            notes.append(f"Inhibit time also as C00324/{number + 1} (ms); cycle time C00356/{5 if number == 1 else 2}.")
        return notes
    if family == EMF2178IB and direction == "rpdo" and number > 1:
        return [f"I-140{number - 1} is not available with 8200 vector and 93XX controllers (manual p. 109): "
                "RPDO2/3 serve the 9300 Servo PLC, Drive PLC and ECS (AIF mode 5, 12 words)."]
    if family == MM4:
        notes = []
        place = MM4_TYPE_PLACE.get((direction, number))
        if place and direction == "rpdo":
            notes.append(f"Transmission type kept in {place[0]} {place[1]} (1 = synchronous 0, 0 = asynchronous 255).")
        elif place:
            notes.append(f"Transmission type also set by {place[0]} {place[1]}.")
        if number == 1:
            return ["Fixed mapping (control word / status word): cannot be changed.", *notes]
        word = 2 if number == 5 else 3
        byte = "low byte" if direction == "rpdo" else "high byte"
        return [f"Also set by P2041.0{word} {byte} (one bit per object, in the mapping sequence).", *notes]
    return []


def setting_refs(profile: Profile, direction: str, number: int) -> list[str]:
    """Vendor codes that shape this PDO beyond its CiA 301 objects (read and shown on its card)."""
    family = profile.family
    if family == LENZE_8400:
        if direction == "rpdo":  # COB-ID source, monitoring time and the response when it is exceeded (ch. 8.3, 8.5)
            return [f"C00353/{number}", f"C00357/{number}", f"C00593/{number}"]
        return [f"C00353/{number}", f"C00324/{number + 1}", f"C00356/{5 if number == 1 else 2}"]
    if family == MM4:  # ch. 5.6: P2041.00/.01 transmission types, .02 = PDO5 mapping (low RPDO, high TPDO), .03 PDO6
        place = MM4_TYPE_PLACE.get((direction, number))
        refs = [place[0]] if place else []
        return refs + ([f"P2041.0{2 if number == 5 else 3}"] if number != 1 else [])
    return []


def p2041_expected(profile: Profile, direction: str, number: int,
                   entries: Sequence[tuple[int, int]]) -> str | None:
    """MICROMASTER: the P2041.02/.03 byte the manual's bit table gives for this mapping, in words."""
    if profile.family != MM4 or number == 1:
        return None
    bits = p2041_bits(direction, entries)
    word = 2 if number == 5 else 3
    byte = "low byte" if direction == "rpdo" else "high byte"
    if bits is None:
        return f"an object of this mapping has no bit in P2041.0{word}"
    return f"this mapping is P2041.0{word} {byte} = 0x{bits:02X} (manual ch. 5.6, tables 5-3/5-4)"


def transmission_note(profile: Profile, direction: str, trans_type: int) -> str | None:
    """Where the manual says this type is not permitted (or behaves specially) for the device."""
    family = profile.family
    if family == LENZE_8400:
        if trans_type in (252, 253):
            return "not permissible on the 8400 motec (RTR-controlled, manual ch. 8.4)"
        if trans_type == 255:
            return "not permissible on the 8400 motec (manual ch. 8.4); use 254"
        if 241 <= trans_type <= 251:
            return "reserved"
    if family == EMF2178IB and direction == "rpdo" and (241 <= trans_type <= 253 or trans_type == 255):
        # p. 109 prints 0 ... 240, 254 for RPDO1 but 0 ... 255 for RPDO2/3; the narrower range is the safe reading
        return "outside the range the EMF2178IB manual prints for RPDO1 (0 ... 240, 254; p. 109)"
    if family == MM4 and direction == "rpdo" and trans_type not in (0, 255):
        return "the MICROMASTER stores only synchronous/asynchronous for RPDOs: reads back as 0 after power-on"
    return None


def mapping_rule_violation(profile: Profile, direction: str, number: int,
                           entries: Sequence[tuple[int, int]]) -> str | None:
    """A device rule the mapping breaks (in words), or None."""
    if profile.family != MM4 or number == 1:
        return None
    order = MM4_RPDO_ORDER if direction == "rpdo" else MM4_TPDO_ORDER
    sequence = [order[entry][0] for entry in entries if entry in order]
    for before, after in pairwise(sequence):
        if after <= before:
            return ("The MICROMASTER needs the objects in its mapping sequence (control/status word 1, speed 2, "
                    "free objects 3-4, torque 5, ... 7), each at most once; reorder the entries (manual ch. 5.4).")
    per_unit = [index for index, _ in entries if index in MM4_PER_UNIT]
    rpm = [index for index, _ in entries if index in (0x6042, 0x6043, 0x6044)]
    if per_unit and rpm and direction == "tpdo":
        return "P2041 bit 15 selects rpm OR per-unit values for a TPDO; do not mix 604x and 605x objects."
    return None


def p2041_bits(direction: str, entries: Sequence[tuple[int, int]]) -> int | None:
    """The P2041.02/.03 byte that selects this mapping (MICROMASTER), or None where an object has no bit."""
    order = MM4_RPDO_ORDER if direction == "rpdo" else MM4_TPDO_ORDER
    value = 0
    for entry in entries:
        if entry not in order:
            return None
        bit = order[entry][1] - (0 if direction == "rpdo" else 8)
        value |= 1 << bit
        if entry[0] in MM4_PER_UNIT:
            value |= 1 << 7
    return value
