"""CiA 306 INI text with line numbers: bytes -> text -> sections of keys, each key knowing its line.

With a :class:`~drivebench.device.formats.eds_quirks.Warnings` collector the quirks of real files are read and
noted; without one (the parameter-set DCF import) each quirk is an error naming file and line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from drivebench.device.formats.eds_quirks import Warnings
from drivebench.device.formats.wide_text import decode_wide
from drivebench.errors import ProfileError
from drivebench.i18n import N_, Text

MAX_EDS_BYTES = 16 * 1024 * 1024
MAX_LINE_CHARS = 64 * 1024
_JUNK = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
_INLINE_COMMENT = re.compile(r"\s;")
_HASH_COMMENT = re.compile(r"\s#")
_KEYWORD_KEYS = frozenset({"accesstype", "datatype", "objecttype", "pdomapping", "subnumber", "objflags",
                           "compactsubobj", "lowlimit", "highlimit"})
"""Keys whose value is a keyword or a number: `` # ...`` after it is a comment (text keys may hold a '#')."""


# --- INI text with line numbers ------------------------------------------------------------------------
@dataclass(slots=True)
class Key:
    name: str
    value: str
    line: int


@dataclass(slots=True)
class Section:
    name: str
    line: int
    keys: dict[str, Key] = field(default_factory=dict)
    """Lower-case key name -> key (CiA 306 key names are case-insensitive)."""

    def get(self, key: str) -> Key | None:
        return self.keys.get(key.lower())


def decode_text(data: bytes, source: str) -> str:
    """Bytes of an EDS -> text: UTF-16/32 (with or without a BOM), else UTF-8, else cp1252, else latin-1."""
    if len(data) > MAX_EDS_BYTES:
        raise ProfileError(Text(N_("file is {count} bytes, more than the {limit} bytes an EDS may have"),
                                count=len(data), limit=MAX_EDS_BYTES),
                           source=source)
    wide = decode_wide(data)
    if wide is not None:
        return wide
    for encoding in ("utf-8-sig", "cp1252"):
        try:
            return data.decode(encoding)
        except UnicodeDecodeError:
            continue
    return data.decode("latin-1")


class _Quirks:
    """Where a quirk goes: a warning (import of a device description) or, without a collector, an error (the
    strict reading the parameter-set DCF import keeps)."""

    def __init__(self, source: str, notes: Warnings | None) -> None:
        self.source = source
        self.notes = notes

    def __call__(self, line: int | None, key: str | None, message: str, strict: str | None = None) -> None:
        if self.notes is None:
            raise ProfileError(strict or message, source=self.source, line=line)
        self.notes.add(line, key, message)


def parse_ini(text: str, source: str, notes: Warnings | None = None) -> dict[str, Section]:
    """INI text -> sections keyed by upper-case name, in file order.

    With ``notes``, quirks are read as INI readers read them and noted: a duplicate key keeps its first value and
    a duplicate section adds its new keys to the first (Windows' profile-string reader, which vendor tools use);
    lines with control characters, without ``=`` or before any section are skipped; ``key: value`` is read like
    ``key=value`` (Python's configparser); `` ;`` after a value starts a comment, and so does `` #`` after the value of
    a keyword or number key (``AccessType=rw # rw;``, noted). Without ``notes`` each of these
    raises ProfileError."""
    if len(text) > MAX_EDS_BYTES:
        raise ProfileError(Text(N_("file has {count} characters, more than {limit}"), count=len(text),
                                limit=MAX_EDS_BYTES), source=source)
    quirk = _Quirks(source, notes)
    sections: dict[str, Section] = {}
    current: Section | None = None
    junk_somewhere = _JUNK.search(text.replace("\r", "").replace("\n", "")) is not None
    # CiA 306 lines end in CR LF; str.splitlines() would also split on NEL, FF, LS... inside values.
    for number, raw in enumerate(re.split(r"\r\n|\r|\n", text), start=1):
        if len(raw) > MAX_LINE_CHARS:
            quirk(number, None, Text(N_("line of {count} characters skipped (an EDS line has at most "
                                        "{limit})"), count=len(raw), limit=MAX_LINE_CHARS),
                  Text(N_("line of {count} characters, more than {limit}"), count=len(raw),
                       limit=MAX_LINE_CHARS))
            continue
        line = raw.strip()
        if junk_somewhere and _JUNK.search(raw):
            if line.strip("\x1a") == "":  # DOS end-of-file mark
                continue
            quirk(number, None, Text(N_("line skipped: control characters (binary junk)")),
                  Text(N_("binary junk (control characters) instead of EDS text")))
            continue
        if not line or line.startswith((";", "#")):
            continue
        if line.startswith("["):
            current = _section(line, number, sections, quirk)
            continue
        if current is None:
            quirk(number, None, Text(N_("line before the first [section] skipped")),
                  Text(N_("key outside of any section")))
            continue
        key, equals, value = line.partition("=")
        if equals and key and ";" not in value and "#" not in value and not key[-1].isspace() \
                and not value[:1].isspace():
            pass  # the common case, read here: "Key=value" without spaces or comments
        else:
            pair = _key_value(line, number, quirk)
            if pair is None:
                continue
            key, value = pair
        lower = key.lower()
        seen = current.keys.get(lower)
        if seen is not None:
            quirk(number, key, Text(N_("duplicate key in [{name}] (first at line {line}): the first value {value!r} "
                                       "is kept"), name=current.name, line=seen.line, value=seen.value),
                  Text(N_("duplicate key {key!r} in [{name}] (first at line {line})"), key=key, name=current.name,
                       line=seen.line))
            continue
        current.keys[lower] = Key(key, value, number)
    return sections


def _hash_comment(key: str, value: str) -> re.Match[str] | None:
    return _HASH_COMMENT.search(value) if "#" in value and key.lower() in _KEYWORD_KEYS else None


def comment_start(key: str, value: str) -> int | None:
    """Where the inline comment of a key's value starts (`` ;``, or `` #`` after a keyword or number), as the
    reader cuts it; None without one."""
    found = [match.start() for match in (_INLINE_COMMENT.search(value), _hash_comment(key, value)) if match]
    return min(found) if found else None


def _section(line: str, number: int, sections: dict[str, Section], quirk: _Quirks) -> Section:
    closing = line.find("]")
    if closing < 0 or len(line) < 3:
        quirk(number, None, Text(N_("section header {line!r} has no ']': read as [{name}]"), line=line,
                                 name=line[1:].strip()),
              Text(N_("bad section header {line!r}"), line=line))
        name = line[1:].strip() or "?"
    else:
        name = line[1:closing].strip()
        if line[closing + 1:].strip() and not line[closing + 1:].strip().startswith(";"):
            quirk(number, None, Text(N_("text after [{name}] ignored"), name=name),
                  Text(N_("bad section header {line!r}"), line=line))
    first = sections.get(name.upper())
    if first is not None:
        quirk(number, None, Text(N_("duplicate section [{name}] (first at line {line}): its keys are added to the "
                                    "first, a key both have keeps the first value"), name=name,
                                 line=first.line), Text(N_("duplicate section [{name}] (first at line "
                                                                      "{line})"), name=name, line=first.line))
        return first
    section = sections[name.upper()] = Section(name, number)
    return section


def _key_value(line: str, number: int, quirk: _Quirks) -> tuple[str, str] | None:
    if "=" in line:
        key, _, value = line.partition("=")
        key, value = key.strip(), value.strip()
    elif ":" in line and quirk.notes is not None:
        key, value = (part.strip() for part in line.split(":", 1))
        quirk(number, key, Text(N_("'key: value' read as 'key=value'")))
    else:
        quirk(number, None, Text(N_("line skipped: no '=' in {value!r}"), value=line[:40]),
              Text(N_("expected 'key=value', a [section] or a ';' comment, got {value!r}"), value=line[:40]))
        return None
    if not key:
        quirk(number, None, Text(N_("line skipped: empty key name")), Text(N_("empty key name")))
        return None
    comment = _INLINE_COMMENT.search(value) if ";" in value else None
    if comment is not None and quirk.notes is not None:
        value = value[:comment.start()].rstrip()
    hashed = _hash_comment(key, value)
    if hashed is not None and quirk.notes is not None:
        quirk(number, key, Text(N_("{value!r} read as {kept!r}: the text from '#' on is a comment"), value=value,
                                kept=value[:hashed.start()].rstrip()))
        value = value[:hashed.start()].rstrip()
    return key, value
