"""A firmware file checked before anything is sent: raw binary or Intel HEX (read with ``intelhex``), and what it is
for, where it says so.

Intel HEX carries addresses and checksums but no identification; a binary carries neither. What a file is for comes
from an optional identification beside it (the vendor's release note as a small JSON "sidecar":
``{"vendor_id": "0x...", "product_code": "0x...", "software_id": "0x..."}``). Where one is given, its vendor and
product must be those the node reports in 0x1018 (sub 1 and 2): a file for another product is refused. Where none is
given the file is accepted, and the check says that DriveBench could not tell which product it is for.
"""

from __future__ import annotations

import io
import json
import zlib
from dataclasses import dataclass, field

from intelhex import HexReaderError, IntelHex, IntelHexError

from drivebench.errors import InvalidValue
from drivebench.i18n import N_, Text, _

MAX_IMAGE = 16 * 1024 * 1024
IDENTITY_KEYS = ("vendor_id", "product_code", "software_id")


@dataclass(frozen=True)
class FirmwareFile:
    name: str
    kind: str
    """``hex`` or ``bin``."""
    image: bytes
    """What goes to 0x1F50: a binary as it is, an Intel HEX file's data from its lowest to its highest address (gaps
    filled with 0xFF)."""
    start_address: int | None
    identity: dict[str, int] = field(default_factory=dict)

    @property
    def crc32(self) -> int:
        return zlib.crc32(self.image)

    def summary(self) -> dict[str, object]:
        return {"name": self.name, "kind": self.kind, "bytes": len(self.image), "crc32": f"0x{self.crc32:08X}",
                "start_address": None if self.start_address is None else f"0x{self.start_address:08X}",
                "identity": {key: f"0x{value:08X}" for key, value in self.identity.items()}}


def _is_hex(name: str, content: bytes) -> bool:
    return name.lower().endswith((".hex", ".ihx", ".ihex")) or content.lstrip()[:1] == b":"


def _hex_image(name: str, content: bytes) -> tuple[bytes, int | None]:
    try:
        text = content.decode("ascii")
    except UnicodeDecodeError as exc:
        raise InvalidValue(_("{file}: not an Intel HEX file (byte {offset} is not ASCII)").format(
            file=name, offset=exc.start)) from exc
    hex_file = IntelHex()
    try:
        hex_file.loadhex(io.StringIO(text))
    except HexReaderError as exc:
        raise InvalidValue(_("{file}: {reason}: nothing was sent. Get the file again from its source.").format(
            file=name, reason=_hex_reason(exc))) from exc
    except IntelHexError as exc:
        raise InvalidValue(_("{file}: not a valid Intel HEX file ({reason})").format(file=name, reason=exc)) from exc
    if not len(hex_file):
        raise InvalidValue(_("{file}: the Intel HEX file holds no data").format(file=name))
    low, high = hex_file.minaddr(), hex_file.maxaddr()
    if high - low + 1 > MAX_IMAGE:
        raise InvalidValue(_("{file}: the data spans {size} bytes (0x{low:08X} ... 0x{high:08X}); at most {limit} "
                             "are taken").format(file=name, size=high - low + 1, low=low, high=high, limit=MAX_IMAGE))
    return hex_file.tobinstr(start=low, end=high), low


def _hex_reason(exc: HexReaderError) -> str:
    line = getattr(exc, "line", None)
    kind = type(exc).__name__
    if kind == "RecordChecksumError":
        return Text(N_("the record on line {line} has a wrong checksum"), line=line)
    if kind == "RecordLengthError":
        return Text(N_("the record on line {line} has a wrong length"), line=line)
    if kind == "RecordTypeError":
        return Text(N_("the record on line {line} has an unknown record type"), line=line)
    if line is not None:
        return Text(N_("line {line} is not a valid Intel HEX record"), line=line)
    return Text(N_("not a valid Intel HEX file ({reason})"), reason=str(exc))


def _identity(name: str, sidecar: str | None) -> dict[str, int]:
    if sidecar is None or not sidecar.strip():
        return {}
    try:
        given = json.loads(sidecar)
    except json.JSONDecodeError as exc:
        raise InvalidValue(_("The identification of {file} is not JSON (line {line}: {reason})").format(
            file=name, line=exc.lineno, reason=exc.msg)) from exc
    if not isinstance(given, dict):
        raise InvalidValue(_("The identification of {file} must be a JSON object").format(file=name))
    unknown = sorted(set(given) - set(IDENTITY_KEYS))
    if unknown:
        raise InvalidValue(_("The identification of {file} has unknown fields: {fields} (known: {known})").format(
            file=name, fields=", ".join(unknown), known=", ".join(IDENTITY_KEYS)))
    identity: dict[str, int] = {}
    for key, value in given.items():
        try:
            number = value if isinstance(value, int) else int(str(value), 0)
        except ValueError as exc:
            raise InvalidValue(_("The identification of {file}: {field} must be a number such as 0x00000001").format(
                file=name, field=key)) from exc
        if not 0 <= number <= 0xFFFFFFFF:
            raise InvalidValue(_("The identification of {file}: {field} must be a 32-bit number").format(
                file=name, field=key))
        identity[key] = number
    return identity


def read_firmware(name: str, content: bytes, sidecar: str | None = None) -> FirmwareFile:
    """The file checked (Intel HEX records and checksums; size); raises :class:`InvalidValue` in words."""
    if not content:
        raise InvalidValue(_("{file} is empty").format(file=name))
    identity = _identity(name, sidecar)
    if _is_hex(name, content):
        image, start = _hex_image(name, content)
        return FirmwareFile(name, "hex", image, start, identity)
    if len(content) > MAX_IMAGE:
        raise InvalidValue(_("{file}: {size} bytes; at most {limit} are taken").format(
            file=name, size=len(content), limit=MAX_IMAGE))
    return FirmwareFile(name, "bin", bytes(content), None, identity)


def refusal(firmware: FirmwareFile, vendor_id: int | None, product_code: int | None) -> str | None:
    """Why the file must not go to a node reporting this vendor and product (None: it may)."""
    for key, reported in (("vendor_id", vendor_id), ("product_code", product_code)):
        wanted = firmware.identity.get(key)
        if wanted is not None and reported is not None and wanted != reported:
            what = _("vendor") if key == "vendor_id" else _("product")
            return _("{file} is for {what} 0x{wanted:08X}, the node reports {what} 0x{reported:08X} (0x1018): "
                     "choose the file for this device.").format(file=firmware.name, what=what, wanted=wanted,
                                                               reported=reported)
    return None
