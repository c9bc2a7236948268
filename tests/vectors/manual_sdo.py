"""The manuals' byte-level SDO examples, as data.

Each vector is one SDO transfer exactly as a manual prints it: the node, the object and its value, and the
request/response frames in order. Tests at every level replay them (the SDO server on a virtual bus, the simulator,
the REST API). Where a manual leaves something out (COB-ID, node, value, a response) the vector fills it in and
says so in ``notes``; where an issue text names another node or value, the manual's example is the vector.

CiA 301 SDO frames always carry 8 data bytes. The MICROMASTER traces print some frames with 7 bytes (the PDF
conversion dropped a trailing ``00``; the trace header still says "8-Data"): those frames are stored with 8.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Direction = Literal["upload", "download"]


@dataclass(frozen=True)
class Frame:
    cob_id: int
    data: bytes
    undefined: tuple[int, ...] = ()
    """Byte positions CiA 301 leaves undefined where the manual prints content (a device may send anything)."""

    def matches(self, cob_id: int, data: bytes) -> bool:
        if cob_id != self.cob_id or len(data) != len(self.data):
            return False
        return all(got == want for pos, (got, want) in enumerate(zip(data, self.data, strict=True))
                   if pos not in self.undefined)

    def __str__(self) -> str:
        return f"0x{self.cob_id:03X}: {self.data.hex(' ').upper()}"


@dataclass(frozen=True)
class SdoVector:
    id: str
    description: str
    source: str
    """Manual and section the frames come from (digest section in brackets)."""
    node: int
    index: int
    subindex: int
    direction: Direction
    value: bytes
    """The object's content: what the upload returns, or what the download stores."""
    exchanges: tuple[tuple[Frame, Frame], ...]
    """(request to the drive, response from the drive), in order."""
    notes: str = ""

    @property
    def request(self) -> Frame:
        return self.exchanges[0][0]

    @property
    def response(self) -> Frame:
        return self.exchanges[0][1]


def _frames(node: int, *pairs: tuple[str, str], undefined: tuple[int, ...] = ()) -> tuple[tuple[Frame, Frame], ...]:
    """SDO1 exchanges of ``node`` from hex strings; ``undefined`` applies to the last response."""
    exchanges = [(Frame(0x600 + node, bytes.fromhex(req)), Frame(0x580 + node, bytes.fromhex(res)))
                 for req, res in pairs]
    if undefined:
        request, response = exchanges[-1]
        exchanges[-1] = (request, Frame(response.cob_id, response.data, undefined))
    return tuple(exchanges)


def _u(value: int, size: int) -> bytes:
    return value.to_bytes(size, "little")


_8400 = "Lenze 8400 motec CANopen communication manual"
_EMF = "Lenze EMF2178IB CANopen communication manual"
_MM4 = "Siemens MICROMASTER 420/430/440 CANopen option module, operating instructions 01/05"

LENZE_8400: tuple[SdoVector, ...] = (
    SdoVector(
        "8400-tv5-read-c00061", "Read C00061 heatsink temperature = 43 °C (INTEGER32, factor 1)",
        f"{_8400}, ch. 9.3.1 [seed000 §7 TV-5]", 5, 0x5FC2, 0, "upload", _u(43, 4),
        _frames(5, ("40 C2 5F 00 00 00 00 00", "43 C2 5F 00 2B 00 00 00"))),
    SdoVector(
        "8400-tv6-write-c00088", "Write C00088 motor rated current = 10.20 A (raw 1020)",
        f"{_8400}, ch. 9.3.2 [seed000 §7 TV-6]", 2, 0x5FA7, 0, "download", _u(1020, 4),
        _frames(2, ("23 A7 5F 00 FC 03 00 00", "60 A7 5F 00 00 00 00 00")),
        "The manual says 'data type U16' and 'U32' for C00088; the telegram writes 4 bytes (0x23)."),
    SdoVector(
        "8400-tv7-read-c00099", "Read C00099 firmware version '01.00.00.00' (11 ASCII characters)",
        f"{_8400}, ch. 9.3.3 [seed000 §7 TV-7]", 12, 0x5F9C, 0, "upload", b"01.00.00.00",
        _frames(12,
                ("40 9C 5F 00 00 00 00 00", "41 9C 5F 00 0B 00 00 00"),
                ("60 00 00 00 00 00 00 00", "00 30 31 2E 30 30 2E 30"),
                ("70 00 00 00 00 00 00 00", "17 30 2E 30 30 00 00 00")),
        "A segmented upload (initiate 0x41 with size 11), which the manual calls 'block parameter'; it is not a "
        "CiA 301 block transfer."),
    SdoVector(
        "8400-tv8-sdo2-rx", "Activate SDO2 of node 4: I-1201/1 COB-ID client->server = 0x644 (bit 31 = 0)",
        f"{_8400}, ch. 13, I-1201 example [seed000 §7 TV-8]", 4, 0x1201, 1, "download", _u(0x644, 4),
        _frames(4, ("23 01 12 01 44 06 00 00", "60 01 12 01 00 00 00 00")),
        "The manual prints only the data bytes; COB-IDs 0x604/0x584 (basic SDO channel) and the CiA 301 download "
        "response are derived."),
    SdoVector(
        "8400-tv8-sdo2-tx", "Activate SDO2 of node 4: I-1201/2 COB-ID server->client = 0x5C4 (bit 31 = 0)",
        f"{_8400}, ch. 13, I-1201 example [seed000 §7 TV-8]", 4, 0x1201, 2, "download", _u(0x5C4, 4),
        _frames(4, ("23 01 12 02 C4 05 00 00", "60 01 12 02 00 00 00 00")),
        "The manual prints only the data bytes; COB-IDs 0x604/0x584 and the response are derived."),
)

LENZE_EMF2178IB: tuple[SdoVector, ...] = (
    SdoVector(
        "emf-tv1-read-c0061", "Read C0061 heatsink temperature = 43 °C (FIX32: 430000)",
        f"{_EMF}, ch. 10.5 [seed001 §7 TV1]", 5, 0x5FC2, 0, "upload", _u(430000, 4),
        _frames(5, ("40 C2 5F 00 00 00 00 00", "43 C2 5F 00 B0 8F 06 00"))),
    SdoVector(
        "emf-tv2-write-c0012", "Write C0012 acceleration time = 20 s, parameter set 1 (FIX32: 200000)",
        f"{_EMF}, ch. 10.5 [seed001 §7 TV2]", 1, 0x5FF3, 0, "download", _u(200000, 4),
        _frames(1, ("23 F3 5F 00 40 0D 03 00", "60 F3 5F 00 00 00 00 00"))),
    SdoVector(
        "emf-tv4-read-c0200", "Read C0200 software product code '82S8212V_14000' of an 8200 vector (14 chars)",
        f"{_EMF}, ch. 10.5 [seed001 §7 TV4]", 1, 0x5F37, 0, "upload", b"82S8212V_14000",
        _frames(1,
                ("40 37 5F 00 00 00 00 00", "41 37 5F 00 0E 00 00 00"),
                ("60 00 00 00 00 00 00 00", "00 38 32 53 38 32 31 32"),
                ("70 00 00 00 00 00 00 00", "11 56 5F 31 34 30 30 30")),
        "The manual gives no COB-IDs for this example; node 1 (SDO1 0x601/0x581) is chosen. Segmented upload: "
        "the last segment 0x11 carries 7 data bytes."),
)

MICROMASTER: tuple[SdoVector, ...] = (
    SdoVector(
        "mm4-ex1-read-r0964.02", "Read r0964.02 (object 0x23C4 sub 2, U16)",
        f"{_MM4}, ch. 3.2.4 tables 3-7/3-8 [seed003 §5.2 example 1]", 3, 0x23C4, 2, "upload", _u(105, 2),
        _frames(3, ("40 C4 23 02 00 00 00 00", "4B C4 23 02 69 00 00 00")),
        "The manual prints the response data as 'dd dd' and gives no node: value 105 and node 3 (MICROMASTER "
        "factory setting) are chosen."),
    SdoVector(
        "mm4-ex2-write-p1203", "Write P1203.00 = 99 (object 0x24B3 sub 0, U16)",
        f"{_MM4}, ch. 3.2.4 tables 3-9/3-10 [seed003 §5.2 example 2]", 3, 0x24B3, 0, "download", _u(99, 2),
        _frames(3, ("2B B3 24 00 63 00 00 00", "60 B3 24 00 00 00 00 00")),
        "The manual gives no node; node 3 (factory setting) is chosen."),
    SdoVector(
        "mm4-p2041.0-node3", "Read P2041.00 = 0xFFFF", f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]",
        3, 0x27F9, 0, "upload", _u(0xFFFF, 2),
        _frames(3, ("40 f9 27 00 00 00 00 00", "4b f9 27 00 ff ff 00 00"))),
    SdoVector(
        "mm4-p2041.1-node3", "Read P2041.01 = 0x00FF", f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]",
        3, 0x27F9, 1, "upload", _u(0x00FF, 2),
        _frames(3, ("40 f9 27 01 00 00 00 00", "4b f9 27 01 ff 00 00 00"))),
    SdoVector(
        "mm4-p2041.2-node3", "Read P2041.02 = 0x2103 (velocity mode mapping)",
        f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]", 3, 0x27F9, 2, "upload", _u(0x2103, 2),
        _frames(3, ("40 f9 27 02 00 00 00 00", "4b f9 27 02 03 21 00 00"))),
    SdoVector(
        "mm4-p2041.3-node3", "Read P2041.03 = 0x4141", f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]",
        3, 0x27F9, 3, "upload", _u(0x4141, 2),
        _frames(3, ("40 f9 27 03 00 00 00 00", "4b f9 27 03 41 41 00 00"))),
    SdoVector(
        "mm4-p2041.2-node4", "Read P2041.02 = 0x1111 (torque mode mapping), node 4",
        f"{_MM4}, ch. 5.8.2 trace [seed003 §5.2]", 4, 0x27F9, 2, "upload", _u(0x1111, 2),
        _frames(4, ("40 f9 27 02 00 00 00 00", "4b f9 27 02 11 11 00 00"))),
    SdoVector(
        "mm4-p2041.3-node4", "Read P2041.03 = 0x4141, node 4", f"{_MM4}, ch. 5.8.2 trace [seed003 §5.2]",
        4, 0x27F9, 3, "upload", _u(0x4141, 2),
        _frames(4, ("40 f9 27 03 00 00 00 00", "4b f9 27 03 41 41 00 00")),
        "The request is printed with 7 bytes; sent with 8."),
    SdoVector(
        "mm4-baud-500", "Write P2010 baud rate = 500 kbit/s (object 0x27DA)",
        f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]", 3, 0x27DA, 0, "download", _u(500, 2),
        _frames(3, ("2b da 27 00 f4 01 00 00", "60 da 27 00 00 00 00 00")),
        "The response is printed with 7 bytes; CiA 301 frames have 8."),
    SdoVector(
        "mm4-node-id-4", "Write P0918 node ID = 4 (object 0x2396)",
        f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]", 3, 0x2396, 0, "download", _u(4, 1),
        _frames(3, ("2f 96 23 00 04 00 00 00", "60 96 23 00 00 00 00 00")),
        "The response is printed with 7 bytes; CiA 301 frames have 8."),
    SdoVector(
        "mm4-save", "Store parameters: write 'save' to 0x1010 sub 1",
        f"{_MM4}, ch. 5.7.2 trace [seed003 §5.2]", 3, 0x1010, 1, "download", b"save",
        _frames(3, ("23 10 10 01 73 61 76 65", "60 10 10 01 00 00 00 00")),
        "The response is printed with 7 bytes; CiA 301 frames have 8."),
    SdoVector(
        "mm4-p2040-0", "Write P2040 telegram failure time = 0 (object 0x27F8)",
        f"{_MM4}, ch. 5.7 step 1 [seed003 §9.1]", 3, 0x27F8, 0, "download", _u(0, 2),
        _frames(3, ("2b f8 27 00 00 00 00 00", "60 f8 27 00 00 00 00 00"))),
    SdoVector(
        "mm4-p1501-bico", "Write P1501.0 = r2091.12 (object 0x25DD := 0x082B000C), expedited without size (0x22)",
        f"{_MM4}, ch. 5.7 step 5 [seed003 §9.1]", 3, 0x25DD, 0, "download", _u(0x082B000C, 4),
        _frames(3, ("22 dd 25 00 0c 00 2b 08", "60 dd 25 00 00 00 00 00")),
        "0x22 = expedited, size not indicated: CiA 301 lets the server take all 4 bytes, although ch. 3.2.4 says "
        "the MICROMASTER needs the size indicated."),
    SdoVector(
        "mm4-rpdo5-map", "Write 0x1604 sub 1 = 0x60400010 (RPDO5 maps the control word)",
        f"{_MM4}, ch. 5.7 step 14 [seed003 §9.1]", 3, 0x1604, 1, "download", _u(0x60400010, 4),
        _frames(3, ("23 04 16 01 10 00 40 60", "60 04 16 01 00 00 00 00")),
        "The response is printed with 7 bytes; CiA 301 frames have 8."),
    SdoVector(
        "mm4-rpdo1-type", "Write 0x1400 sub 2 = 0xFF (RPDO1 transmission type)",
        f"{_MM4}, ch. 5.7 step 7 [seed003 §9.1]", 3, 0x1400, 2, "download", _u(0xFF, 1),
        _frames(3, ("2f 00 14 02 ff 00 00 00", "60 00 14 02 00 00 00 00"))),
    SdoVector(
        "mm4-mode-torque", "Write 0x6060 modes of operation = 4 (profile torque)",
        f"{_MM4}, ch. 5.8 step 8 [seed003 §9.2]", 3, 0x6060, 0, "download", _u(4, 1),
        _frames(3, ("2f 60 60 00 04 00 00 00", "60 60 60 00 00 00 00 00")),
        "The response is printed with 7 bytes; CiA 301 frames have 8."),
    SdoVector(
        "mm4-mode-display", "Read 0x6061 modes of operation display = 4",
        f"{_MM4}, ch. 5.8 step 9 [seed003 §9.2]", 3, 0x6061, 0, "upload", _u(4, 1),
        _frames(3, ("40 61 60 00 00 00 00 00", "4f 61 60 00 04 00 bf 84"), undefined=(5, 6, 7)),
        "Bytes 5..7 of a 1-byte expedited response carry no data (CiA 301: undefined); the device sent "
        "'00 bf 84', a CiA 301 server may send zeros."),
)

ALL: tuple[SdoVector, ...] = LENZE_8400 + LENZE_EMF2178IB + MICROMASTER
