"""A DCF written over the original device description: every section, key, comment, blank line, line end and the
encoding stay as they were; only the values asked for change.

``ParameterValue`` (and ``DefaultValue`` where asked) of the objects given, and ``[DeviceComissioning]``
NodeID/Baudrate/NodeName, are replaced in place. A key the object's section lacks is added after its last key; a
CompactSubObj array's values go to its ``[xxxxValue]`` section (CiA 306 4.6.4), made when missing. Where a key or
section is there twice, the first is the one tools read (:func:`drivebench.device.formats.eds.parse_ini`) and the one
set.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from drivebench.device.formats.eds import decode_text
from drivebench.device.formats.wide_text import wide_encoding

Address = tuple[int, int]
_LINE = re.compile(r"(\r\n|\r|\n)")


@dataclass
class _Section:
    name: str
    header: int
    """Index of the header line in the line list."""
    keys: dict[str, int] = field(default_factory=dict)
    """Lower-case key -> index of its (first) line."""
    last: int = 0
    """Index of the section's last key line (or the header)."""


class _Lines:
    def __init__(self, text: str) -> None:
        parts = _LINE.split(text)
        self.lines = parts[0::2]
        self.ends = [*parts[1::2], ""]
        self.newline = next((end for end in self.ends if end), "\r\n")
        self.sections: dict[str, _Section] = {}
        self._index()

    def _index(self) -> None:
        self.sections = {}
        current: _Section | None = None
        for number, raw in enumerate(self.lines):
            line = raw.strip()
            if line.startswith("[") and "]" in line:
                name = line[1:line.index("]")].strip().upper()
                current = self.sections.setdefault(name, _Section(name, number, last=number))
            elif current is not None and "=" in line and not line.startswith((";", "#")):
                key = line.split("=", 1)[0].strip().lower()
                current.keys.setdefault(key, number)
                current.last = max(current.last, number)

    def value(self, section: str, key: str) -> str | None:
        found = self.sections.get(section.upper())
        number = found.keys.get(key.lower()) if found is not None else None
        return None if number is None else self.lines[number].split("=", 1)[1].split(";")[0].split("#")[0].strip()

    def holds_a_var(self, section: str) -> bool:
        """``[section]`` is a whole VAR or DOMAIN (a ``[...sub0]`` beside it is stray: the reader skips it)."""
        return self.value(section, "DataType") is not None and _var_type(self.value(section, "ObjectType") or "")

    def set(self, section: str, key: str, value: str) -> None:
        found = self.sections.get(section.upper())
        if found is None:
            self.add_section(section, [(key, value)])
            return
        number = found.keys.get(key.lower())
        if number is not None:
            raw = self.lines[number]
            head, rest = raw.split("=", 1)
            comment = re.search(r"\s;", rest)
            spacing = re.match(r"\s*", rest)
            lead = spacing.group(0) if spacing else ""
            self.lines[number] = f"{head}={lead}{value}{rest[comment.start():] if comment else ''}"
            return
        self.insert(found.last + 1, [f"{key}={value}"])

    def insert(self, at: int, new: list[str]) -> None:
        if at > 0 and self.ends[at - 1] == "":  # the file's last line had no line end
            self.ends[at - 1] = self.newline
            self.ends[at:at] = [self.newline] * (len(new) - 1) + [""]
        else:
            self.ends[at:at] = [self.newline] * len(new)
        self.lines[at:at] = new
        self._index()

    def add_section(self, name: str, keys: list[tuple[str, str]]) -> None:
        block = [f"[{name}]", *(f"{k}={v}" for k, v in keys)]
        at = len(self.lines)
        while at > 0 and not self.lines[at - 1].strip() and self.ends[at - 1] == "":
            at -= 1  # before the empty remainder after the final line end
        self.insert(at, (["", *block] if at and self.lines[at - 1].strip() else block))

    def text(self) -> str:
        return "".join(line + end for line, end in zip(self.lines, self.ends, strict=True))


def _var_type(text: str) -> bool:
    """ObjectType text of a VAR (0x7) or DOMAIN (0x2)."""
    text = text.lower()
    if text in ("var", "domain"):
        return True
    try:
        return int(text, 16 if text.startswith("0x") else 10) in (0x2, 0x7)
    except ValueError:
        return False


def file_encoding(data: bytes) -> tuple[str, bytes]:
    """The encoding to write a file back in, and its BOM (empty without one)."""
    wide = wide_encoding(data)
    if wide is not None:  # UTF-16/32 written back as read, with the BOM the file had (if any)
        return wide, data[:len("\ufeff".encode(wide))] if data.startswith("\ufeff".encode(wide)) else b""
    if data.startswith(b"\xef\xbb\xbf"):
        return "utf-8", b"\xef\xbb\xbf"
    for encoding in ("utf-8", "cp1252"):
        try:
            data.decode(encoding)
            return encoding, b""
        except UnicodeDecodeError:
            continue
    return "latin-1", b""


def patch_dcf(original: bytes, source: str, values: Mapping[Address, str], *, defaults: bool = False,
              commissioning: Mapping[str, str] | None = None) -> bytes:
    """``original`` with ``ParameterValue`` (and with ``defaults`` also ``DefaultValue``) set to ``values`` (EDS
    text by (index, subindex)) and the ``[DeviceComissioning]`` keys given; nothing else changes."""
    encoding, bom = file_encoding(original)
    lines = _Lines(decode_text(original, source))
    for (index, sub), text in values.items():
        own = f"{index:04X}SUB{sub:X}"
        head = lines.sections.get(f"{index:04X}")
        compact = head is not None and "compactsubobj" in head.keys and sub > 0 and own not in lines.sections
        if compact:
            value_section = f"{index:04X}Value"
            if value_section.upper() not in lines.sections:
                lines.add_section(value_section, [("NrOfEntries", "0")])
            lines.set(value_section, str(sub), text)
            found = lines.sections[value_section.upper()]
            entries = sum(1 for key in found.keys if key.isdigit())
            lines.set(value_section, "NrOfEntries", str(entries))
            continue
        whole_var = sub == 0 and head is not None and lines.holds_a_var(f"{index:04X}")
        section = own if (own in lines.sections and not whole_var) or sub > 0 else f"{index:04X}"
        lines.set(section, "ParameterValue", text)
        if defaults:
            lines.set(section, "DefaultValue", text)
    for key, text in (commissioning or {}).items():
        lines.set("DeviceComissioning", key, text)
    return bom + lines.text().encode(encoding, errors="replace")
