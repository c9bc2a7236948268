"""A regenerated EDS written over the file the profile was read from: what nobody edited stays as it was read.

The profile is compared with the one its file gives (read again): both are written by
:func:`~drivebench.device.formats.eds_export.export_eds` and the keys whose text differs are the edits. Only those
change in the original text: a changed value is written at its line in the file's own style (hex or decimal, digit
count, ``0x``/``0X``, letter case; the spacing around ``=`` and an inline comment stay), a new key goes after the
last key of its section, a key the profile no longer has is removed, a new object's sections go at the end and its
index into its object list. Every other byte (section and key order, raw value text, comment and blank lines, line
ends, encoding and BOM) is the file's. An unedited profile gives the file back byte for byte; no header line of ours
is added.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from drivebench.device.formats.dcf_patch import file_encoding
from drivebench.device.formats.eds import OBJECT_LISTS, decode_text, parse_ini, read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.eds_ini import comment_start
from drivebench.device.profiles.profile import Profile
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE

_LINE_END = re.compile(r"(\r\n|\r|\n)")
_SUB_SECTION = re.compile(r"^([0-9A-F]{4})SUB([0-9A-F]{1,2})$")
_HEX = re.compile(r"^([+-]?)0([xX])([0-9A-Fa-f]+)$")
_OBJECT_SECTION = re.compile(r"^[0-9A-F]{4}(SUB[0-9A-F]{1,2}|NAME|VALUE|DENOTATION|OBJECTLINKS)?$")
_DECIMAL = re.compile(r"^[+-]?\d+$")
_LISTS = {name.upper() for name in OBJECT_LISTS}

Keys = dict[str, dict[str, tuple[str, str]]]
"""Section (normalised upper-case name) -> lower-case key -> (key name, value text)."""


def section_id(name: str) -> str:
    """``[1018SUB01]``, ``[1018sub1]`` -> ``1018SUB1``; other sections by their upper-case name."""
    upper = name.strip().upper()
    found = _SUB_SECTION.match(upper)
    return f"{found.group(1)}SUB{int(found.group(2), 16):X}" if found else upper


def _keys(text: str) -> tuple[Keys, dict[str, str]]:
    """An export's keys, and the name each section has in it."""
    sections = parse_ini(text, "export").values()
    return ({section_id(s.name): {k: (key.name, key.value) for k, key in s.keys.items()} for s in sections},
            {section_id(s.name): s.name for s in sections})


@dataclass
class _Place:
    header: int
    keys: dict[str, int] = field(default_factory=dict)
    last: int = 0


class _Text:
    """The original lines, their line ends and where each section and (first) key is."""

    def __init__(self, text: str) -> None:
        parts = _LINE_END.split(text)
        self.lines: list[str | None] = list(parts[0::2])
        self.ends = [*parts[1::2], ""]
        self.newline = next((end for end in self.ends if end), "\r\n")
        self.places: dict[str, _Place] = {}
        self.after: dict[int, list[str]] = {}
        """Lines added after a line of the file."""
        self.added: list[str] = []
        """Lines added at the end (new sections)."""
        current: _Place | None = None
        for number, raw in enumerate(parts[0::2]):
            line = raw.strip()
            if line.startswith("["):
                name = section_id(line[1:line.index("]")] if "]" in line else line[1:])
                current = self.places.setdefault(name, _Place(number, last=number))
            elif current is not None and line and not line.startswith((";", "#")) and "=" in line:
                current.keys.setdefault(line.split("=", 1)[0].strip().lower(), number)
                current.last = max(current.last, number)

    def value(self, section: str, key: str) -> str | None:
        place = self.places.get(section)
        number = place.keys.get(key) if place else None
        raw = self.lines[number] if number is not None else None
        return None if raw is None else _split(raw)[1]

    def set(self, section: str, key_name: str, text: str, signed_bits: int | None = None) -> None:
        place = self.places[section]
        number = place.keys.get(key_name.lower())
        raw = self.lines[number] if number is not None else None
        if number is None or raw is None:
            self.after.setdefault(place.last, []).append(f"{key_name}={text}")
            return
        head, old, tail = _split(raw)
        self.lines[number] = f"{head}{styled(old, text, signed_bits)}{tail}"

    def remove(self, section: str, key: str) -> None:
        place = self.places.get(section)
        number = place.keys.get(key) if place else None
        if number is not None:
            self.lines[number] = None

    def remove_section(self, section: str) -> None:
        place = self.places.pop(section, None)
        if place is None:
            return
        for number in range(place.header, place.last + 1):
            self.lines[number] = None
        following, before = place.last + 1, place.header - 1
        if following < len(self.lines) - 1 and self.blank(following):
            self.lines[following] = None  # the blank line that separated it from the next section
        elif before >= 0 and self.blank(before):
            self.lines[before] = None

    def blank(self, number: int) -> bool:
        line = self.lines[number]
        return line is not None and not line.strip()

    def add_section(self, name: str, keys: list[tuple[str, str]]) -> None:
        self.added.extend(["", f"[{name}]", *(f"{k}={v}" for k, v in keys)])

    def text(self) -> str:
        out: list[str] = []
        for number, (line, end) in enumerate(zip(self.lines, self.ends, strict=True)):
            extra = self.after.get(number, [])
            if line is not None:
                out.append(line + (end or (self.newline if extra else "")))
            out.extend(added + (self.newline if n < len(extra) - 1 or end else "")
                       for n, added in enumerate(extra))
        written = "".join(out)
        if self.added:
            if written and not written.endswith(("\n", "\r")):
                written += self.newline
            block = self.added[1:] if not written or written.endswith(self.newline * 2) else self.added
            written += self.newline.join(block) + self.newline
        return written


def _split(raw: str) -> tuple[str, str, str]:
    """A key line -> (``key=`` with its spacing, the value, the spacing and comment after it)."""
    head, _, rest = raw.partition("=")
    lead = rest[:len(rest) - len(rest.lstrip())]
    body = rest[len(lead):]
    cut = comment_start(head.strip(), body)
    value = body[:cut].rstrip() if cut is not None else body.rstrip()
    return f"{head}={lead}", value, body[len(value):]


def styled(old: str, new: str, signed_bits: int | None = None) -> str:
    """``new`` (as the exporter writes it) in the style of ``old``: hex with its prefix, letter case and digit
    count, or decimal. A negative number goes into hex as the two's complement of its signed type's width
    (``signed_bits``: what the reader takes back, CiA 306 and :func:`eds_quirks.fit_int`), with at least that many
    digits; without a width it is written in decimal (``0x0`` of an INTEGER8 edited to -1 as ``0xF`` read back 15)."""
    number = int(new, 0) if _HEX.match(new) or _DECIMAL.match(new) else None
    if number is None:
        return new
    hexed = _HEX.match(old.strip())
    if hexed is not None and (number >= 0 or signed_bits):
        _, x, digits = hexed.groups()
        width = len(digits)
        if number < 0 and signed_bits:
            number += 1 << signed_bits
            width = max(width, signed_bits // 4)
        text = f"{number:0{width}X}"
        lower = any(c.isalpha() for c in digits) and digits.lower() == digits
        return f"0{x}{text.lower() if lower else text}"
    return str(number)


def _signed_bits(data_type: str) -> int | None:
    """The width of a signed integer type named by its EDS ``DataType`` code, else None."""
    try:
        found = DATA_TYPE_BY_CODE.get(int(data_type, 0))
    except ValueError:
        return None
    return found.size * 8 if found is not None and found.is_signed and found.size else None


def _listed(keys: Keys) -> dict[int, str]:
    """Object index -> the object list that names it (in an export's lists)."""
    found: dict[int, str] = {}
    for name in _LISTS:
        for key, (_, value) in keys.get(name, {}).items():
            if key.isdigit():
                found[int(value, 0)] = name
    return found


def _index(text: str | None) -> int | None:
    try:
        return int((text or "").strip(), 0)
    except ValueError:
        return None


def _relist(text: _Text, before: Keys, after: Keys) -> None:
    """Objects added or removed: their index goes into (or out of) an object list of the file, the list counted
    and numbered again."""
    was, now = _listed(before), _listed(after)
    if was.keys() == now.keys():
        return
    for name in OBJECT_LISTS:
        upper = name.upper()
        place = text.places.get(upper)
        numbered = sorted((k for k in place.keys if k.isdigit()), key=int) if place else []
        kept = [value for value in (text.value(upper, key) for key in numbered)
                if value is not None and _index(value) not in was.keys() - now.keys()]
        indices = kept + [f"0x{i:04X}" for i in sorted(now.keys() - was.keys()) if now[i] == upper]
        numbering = [(str(n), value) for n, value in enumerate(indices, start=1)]
        listing = [f"{n}={value}" for n, value in numbering]
        if place is None:
            if indices:
                text.add_section(name, [("SupportedObjects", str(len(indices))), *numbering])
            continue
        for key in numbered:
            text.remove(upper, key)
        if numbered and listing:
            first = place.keys[numbered[0]]
            text.lines[first] = listing[0]
            text.after.setdefault(first, []).extend(listing[1:])
        elif listing:
            text.after.setdefault(place.keys.get("supportedobjects", place.header), []).extend(listing)
        if "supportedobjects" in place.keys:
            text.set(upper, "SupportedObjects", str(len(indices)))
        else:
            text.after.setdefault(place.header, []).insert(0, f"SupportedObjects={len(indices)}")


def rewrite_eds(profile: Profile, original: bytes, source: str) -> bytes:
    """``profile`` as an EDS written over ``original`` (the bytes it was read from): only its edits change."""
    baseline = read_eds(original, source=source).profile.model_copy(update={"id": profile.id})
    (before, _), (after, names) = _keys(export_eds(baseline)), _keys(export_eds(profile))
    if before == after:
        return original
    encoding, bom = file_encoding(original)
    text = _Text(decode_text(original, source))
    _relist(text, before, after)
    for section, keys in after.items():
        if section in _LISTS:
            continue
        old = before.get(section, {})
        if section not in text.places:
            if section not in before:
                text.add_section(names[section], list(keys.values()))
            continue
        bits = _signed_bits(keys.get("datatype", ("", ""))[1])
        for key, (name, value) in keys.items():
            if old.get(key, ("", None))[1] != value:
                text.set(section, name, value, bits)
    gone = {f"{o.index:04X}" for o in baseline.objects} - {f"{o.index:04X}" for o in profile.objects}
    for section in [name for name in text.places if name[:4] in gone and _OBJECT_SECTION.match(name)]:
        text.remove_section(section)
    for section, keys in before.items():
        if section in _LISTS:
            continue
        if section not in after:
            text.remove_section(section)
            continue
        for key in keys.keys() - after[section].keys():
            text.remove(section, key)
    return bom + text.text().encode(encoding, errors="replace")
