"""CiA 306 EDS/DCF import: an electronic data sheet -> a :class:`Profile`.

The INI text is parsed by :mod:`drivebench.device.formats.eds_ini` (not with configparser) so every warning and error
names the file and line.

Decisions where CiA 306 leaves room:

* Encoding: UTF-8 (with or without BOM) first, then Windows-1252, then ISO 8859-1 (CiA 306 files are 8-bit text;
  German vendors write ``°C``/``ä``, Windows tools ``€`` and curly quotes, which latin-1 would turn into control
  characters). Control characters other than tab are "binary junk" and rejected with their line.
* ``;`` (or ``#``) starts a comment at the beginning of a line (CiA 306 4.1) and, after a space, inside a line
  (what canopen's configparser reads); a ``;`` right after a character is part of the value.
* Quirks of real files (limits that do not fit the type, numbers with trailing text, missing keys, counts that
  do not match, duplicate keys...) are read as :mod:`drivebench.device.formats.eds_quirks` says, each with a warning
  (:func:`read_eds`); only a file with no usable object dictionary is refused.
* Integers: decimal, ``0x`` hex, or octal with a leading ``0`` (CiA 306 4.6.3). Hex limits of signed types are
  two's complement (``LowLimit=0x80000000`` of an INTEGER32 is -2147483648).
* ``$NODEID`` formulas are kept as formulas (``ObjectEntry.default_expr``; a formula ``ParameterValue`` stays a
  string) so a DCF for any node id can be written; :func:`resolve_node_expr` evaluates one.
* ``CompactSubObj`` arrays are expanded (sub 0 ``NrOfObjects``, sub n ``<ParameterName><n>`` unless ``[xxxxName]``
  names it); ``ObjectType=0x2`` (DOMAIN) becomes a VAR of data type DOMAIN.
* ``Unit``, ``Factor`` and ``Description`` (canopen's extensions) are read; with a factor, limits and defaults become
  engineering units like every other profile. A ``Factor`` that gives 1 or no number (``Factor=ERROR``) is kept as
  written with the object's other keys without a model field (``ObjectEntry.section_keys``).
* Sections the model has no field for (``[DummyUsage]``, ``[DeviceComissioning]``, ``[Tools]`` ...) and the
  ``[FileInfo]``/``[DeviceInfo]`` keys without a model field go to ``Profile.extra_sections`` verbatim.
* ``[DriveBench]`` (our own section, ignored by other tools) carries the profile id, family, version and source.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivebench.device.formats.eds_ini import MAX_EDS_BYTES, Key, Section, decode_text, parse_ini
from drivebench.device.formats.eds_quirks import (
    OBJECT_TYPE_NAMES,
    ImportWarning,
    Warnings,
    fit_int,
    node_expr,
    parse_int_strict,
    read_access,
    read_int,
    read_value,
    type_name,
)
from drivebench.device.profiles.profile import Access, Features, Identity, ObjectEntry, Profile, Value
from drivebench.errors import ProfileError
from drivebench.i18n import N_, Text
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE, DataType

__all__ = ["MAX_EDS_BYTES", "ImportWarning", "ImportedEds", "Key", "Section", "decode_text", "import_eds",
           "node_expr", "parse_ini", "parse_int", "parse_value", "read_eds", "resolve_node_expr"]

BAUD_RATES_KBIT = (10, 20, 50, 125, 250, 500, 800, 1000)
OBJECT_LISTS = ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects")
_KEPT_LISTING = re.compile(r"^0x[0-9A-F]{4}$", re.IGNORECASE)
OBJECT_TYPE_CODES = {"VAR": 0x7, "ARRAY": 0x8, "RECORD": 0x9}
DEFAULT_FAMILY = "eds"
OWN_SECTION = "DriveBench"
COMPACT_SUB0_NAME = "NrOfObjects"
MANDATORY_OBJECTS = (0x1000, 0x1001, 0x1018)

_INDEX_SECTION = re.compile(r"^([0-9A-F]{4})(?:SUB([0-9A-F]{1,2})|(NAME|VALUE|DENOTATION))?$")
_MODEL_KEYS = {"parametername", "objecttype", "datatype", "accesstype", "defaultvalue", "parametervalue",
               "lowlimit", "highlimit", "pdomapping", "objflags", "denotation", "unit", "factor", "description",
               "subnumber", "compactsubobj"}
_HEAD_KEYS = {"parametername", "objecttype", "subnumber", "objflags", "compactsubobj"}
"""Keys of an ARRAY/RECORD's own section the model reads; the others are kept (``ObjectEntry.object_keys``)."""
_MAPPED_DEVICE_INFO = {"vendorname", "vendornumber", "productname", "productnumber", "revisionnumber",
                       "ordercode", "nrofrxpdo", "nroftxpdo", *(f"baudrate_{b}" for b in BAUD_RATES_KBIT)}


def range_object_list(index: int) -> str:
    """The object list CiA 306 puts an index in: 0x1000/0x1001/0x1018 mandatory, 0x2000..0x5FFF manufacturer, the
    rest optional."""
    if index in MANDATORY_OBJECTS:
        return "MandatoryObjects"
    return "ManufacturerObjects" if 0x2000 <= index <= 0x5FFF else "OptionalObjects"


# --- values --------------------------------------------------------------------------------------------
parse_int = parse_int_strict


def resolve_node_expr(text: str, node_id: int) -> int:
    """Evaluate a ``$NODEID`` formula for one node (``$NODEID+0x180``, 5 -> 0x185)."""
    constant = node_expr(text)
    if constant is None:
        return parse_int(text)
    return constant + node_id


def parse_value(data_type: DataType, text: str) -> Value:
    """An EDS value of ``data_type`` -> raw model value, strictly (CiA 306 forms only). Raises ValueError."""
    if data_type.is_integer and not (data_type is DataType.BOOLEAN and text.strip().lower() in ("true", "false")):
        number = parse_int(text)
        fitted, note = fit_int(data_type, number)
        if fitted is None or (note and not (data_type.is_signed and text.strip().lower().startswith("0x"))):
            low, high = data_type.raw_limits() or (0, 0)
            raise ValueError(Text(N_("{value} does not fit {type} ({low}..{high})"), value=text, type=data_type.value,
                                  low=low, high=high))
        return fitted
    value, note = read_value(data_type, text)
    if value is None or note:
        raise ValueError(Text(N_("{value!r} is not a {type} value"), value=text, type=data_type.value))
    return value


def _number(text: str) -> int | None:
    try:
        return parse_int(text)
    except ValueError:
        return None


# --- defaults of what export writes and import need not keep ----------------------------------------------
def file_info_defaults(profile: Profile) -> dict[str, str]:
    return {"FileName": f"{profile.id}.eds", "FileVersion": "1", "FileRevision": "0", "EDSVersion": "4.0",
            "Description": profile.identity.product_name, "CreatedBy": "DriveBench"}


DEVICE_INFO_DEFAULTS = {"SimpleBootUpMaster": "0", "SimpleBootUpSlave": "1", "Granularity": "8",
                        "DynamicChannelsSupported": "0", "GroupMessaging": "0", "LSS_Supported": "0"}
EMPTY_IDENTITY_KEYS = {name.lower(): name for name in ("VendorNumber", "ProductNumber", "RevisionNumber",
                                                       "OrderCode")}
"""Identity keys a file may leave empty (``OrderCode=``): the model holds no value, the key is kept as written."""
EMPTY_PRODUCT_NAME = {"ProductName": ""}
"""``ProductName=`` (lely-core's DCFs): the profile is named after the file (with a warning) and the key is kept
empty, as written."""


def spelled_as(names: dict[str, str], keys: dict[str, str]) -> dict[str, str]:
    """``keys`` with each name of ``names`` spelled as there: CiA 306 key names are case-insensitive, so a file's
    ``SimpleBootupSlave=0`` is the ``SimpleBootUpSlave`` an export writes (once, with the file's value)."""
    spelling = {name.lower(): name for name in names}
    return {spelling.get(key.lower(), key): value for key, value in keys.items()}


def kept_object_type(entry: ObjectEntry, text: str) -> ObjectEntry:
    """``entry`` (read as a VAR) with the file's ``ObjectType`` text to write back."""
    return entry.model_copy(update={"value_texts": {**(entry.value_texts or {}), "ObjectType": text}})


# --- import --------------------------------------------------------------------------------------------
@dataclass
class ImportedEds:
    """A device description read with quirks: the profile and the readings applied to get it."""

    profile: Profile
    warnings: list[ImportWarning]


class _Reader:
    """One import: the parsed sections, and the warnings of the readings applied."""

    def __init__(self, sections: dict[str, Section], source: str, notes: Warnings) -> None:
        self.sections = sections
        self.source = source
        self.notes = notes
        self.list_names: dict[int, str] = {}
        self.unsectioned: dict[str, dict[str, str]] = {}
        """Listings of objects without a section, by object list: ``{"OptionalObjects": {"0x6505": "104"}}`` (the
        index and the entry's number; kept in ``Profile.extra_sections`` so every export lists them again)."""
        """The object list each listed index is in."""

    def fail(self, detail: str, line: int | None) -> ProfileError:
        return ProfileError(detail, source=self.source, line=line)

    def warn(self, line: int | None, key: str | None, message: str, *, address: tuple[int, int] | None = None,
             limits: bool = False) -> None:
        self.notes.add(line, key, message, address=address, limits=limits)

    def integer(self, key: Key, fallback: int | None = None, *, what: str = "") -> int | None:
        """A whole number key; a quirk is read with a warning, no number at all gives ``fallback``."""
        try:
            value, note = read_int(key.value)
        except ValueError:
            self.warn(key.line, key.name, Text(N_("{value!r} is not a number: {reading}"), value=key.value,
                                               reading=what or Text(N_("ignored"))))
            return fallback
        if note:
            self.warn(key.line, key.name, Text(N_("{value!r} {note}"), value=key.value, note=note))
        return value

    # object lists ---------------------------------------------------------------------------------------
    def listed_indices(self) -> dict[int, Key]:
        if not any(n.upper() in self.sections for n in OBJECT_LISTS):
            self.warn(1, None, Text(N_("no [MandatoryObjects], [OptionalObjects] or [ManufacturerObjects]: every "
                                       "object section of the file is read")))
        listed: dict[int, Key] = {}
        for list_name in OBJECT_LISTS:
            section = self.sections.get(list_name.upper())
            if section is None:
                continue
            numbered = sorted((k for k in section.keys.values() if k.name.isdigit()), key=lambda k: int(k.name))
            for key in section.keys.values():  # ``0x6505=104``: a kept listing as an XDD gives it back
                if not key.name.isdigit() and key.name.lower() != "supportedobjects" and _KEPT_LISTING.match(key.name):
                    self.unsectioned.setdefault(list_name, {})[key.name] = key.value
            count_key = section.get("SupportedObjects")
            count = self.integer(count_key) if count_key is not None else None
            if count_key is None:
                self.warn(section.line, "SupportedObjects", Text(N_("[{name}] has no SupportedObjects=: the {count} "
                                                                    "numbered entries are read"), name=section.name,
                                                                 count=len(numbered)))
            elif count != len(numbered):
                self.warn(count_key.line, count_key.name, Text(N_("SupportedObjects={value} but [{name}] lists "
                                                                  "{count} objects: the {count} listed are read"),
                                                               value=count_key.value, name=section.name,
                                                               count=len(numbered)))
            for key in numbered:
                index = self.integer(key, what=Text(N_("entry skipped")))
                if index is None:
                    continue
                if not 0x1000 <= index <= 0xFFFF:
                    self.warn(key.line, key.name, Text(N_("object index 0x{index:04X} is outside 0x1000..0xFFFF: "
                                                          "skipped"), index=index))
                    continue
                if index in listed:
                    self.warn(key.line, key.name, Text(N_("object 0x{index:04X} listed twice (first at line {line})"),
                                                       index=index, line=listed[index].line))
                    continue
                listed[index] = key
                self.list_names[index] = list_name
        return listed

    # objects --------------------------------------------------------------------------------------------
    def objects(self) -> list[ObjectEntry]:
        listed = self.listed_indices()
        by_index: dict[int, Section] = {}
        subs: dict[int, dict[int, Section]] = {}
        aux: dict[tuple[int, str], Section] = {}
        for upper, section in self.sections.items():
            match = _INDEX_SECTION.match(upper)
            if match is None:
                continue
            index = int(match.group(1), 16)
            if match.group(2) is not None:
                subs.setdefault(index, {})[int(match.group(2), 16)] = section
            elif match.group(3) is not None:
                aux[(index, match.group(3))] = section
            elif section.keys:
                by_index[index] = section
            else:
                self.warn(section.line, None, Text(N_("[{name}] has no keys: skipped"), name=section.name))
        for index, key in listed.items():
            if index not in by_index and index not in subs:
                self.warn(key.line, key.name, Text(N_("object 0x{index:04X} is listed but has no [{index:04X}] "
                                                      "section: skipped"), index=index))
                self.unsectioned.setdefault(self.list_names[index], {})[f"0x{index:04X}"] = key.name
        for index, sub_sections in subs.items():
            if index not in by_index and index >= 0x1000:
                first = min(sub_sections.values(), key=lambda s: s.line)
                self.warn(first.line, None, Text(N_("[{name}] belongs to no object section [{index:04X}]: read as a "
                                                    "RECORD named 'Object 0x{index:04X}'"), name=first.name,
                                                 index=index))
                by_index[index] = Section(f"{index:04X}", first.line, {
                    "parametername": Key("ParameterName", f"Object 0x{index:04X}", first.line),
                    "objecttype": Key("ObjectType", "0x9", first.line)})
        if listed:
            for index in sorted(set(by_index) - set(listed)):
                if index >= 0x1000:
                    self.warn(by_index[index].line, None, Text(N_("object section [{name}] is in no object list "
                                                                  "([MandatoryObjects] ...): read"),
                                                               name=by_index[index].name))
        entries: list[ObjectEntry] = []
        for index in sorted(i for i in by_index if i >= 0x1000):
            read = self.object(index, by_index[index], subs.get(index, {}), aux)
            list_name = self.list_names.get(index, range_object_list(index))
            if read and list_name != range_object_list(index):
                read[0] = read[0].model_copy(update={"object_list": list_name})
            entries.extend(read)
        return entries

    def object_type(self, index: int, section: Section, subs: dict[int, Section]) -> int | None:
        type_key = section.get("ObjectType")
        if type_key is None:
            return 0x9 if subs else 0x7  # CiA 306 4.6.3.2: a missing ObjectType is VAR
        named = OBJECT_TYPE_NAMES.get(type_key.value.strip().lower())
        object_type = named if named is not None else self.integer(type_key, what=Text(N_("read as VAR")))
        if object_type in (0x0, 0x5, 0x6):
            self.warn(type_key.line, type_key.name, Text(N_("object 0x{index:04X} is a type definition (NULL, "
                                                            "DEFTYPE or DEFSTRUCT), no data: skipped"), index=index))
            return None
        if object_type not in (0x2, 0x7, 0x8, 0x9):
            guess = 0x9 if subs else 0x7
            self.warn(type_key.line, type_key.name, Text(N_("ObjectType={value} is not VAR 0x7, DOMAIN 0x2, ARRAY "
                                                            "0x8 or RECORD 0x9: read as {type}"),
                                                         value=type_key.value, type="RECORD" if subs else "VAR"))
            return guess
        if object_type in (0x2, 0x7) and subs:
            first = min(subs.values(), key=lambda s: s.line)
            if section.get("DataType") is not None or object_type == 0x2:  # a whole VAR: the sections are stray
                self.warn(first.line, None, Text(N_("object 0x{index:04X} is a VAR but has sub-object sections "
                                                    "([{name}] ...): they are skipped, the VAR is read"),
                                                 index=index, name=first.name))
                return object_type
            self.warn(type_key.line, type_key.name, Text(N_("object 0x{index:04X} is a VAR but has sub-object "
                                                            "sections ([{name}] ...): read as a RECORD"), index=index,
                                                         name=first.name))
            return 0x9
        return object_type

    def object(self, index: int, section: Section, subs: dict[int, Section],
               aux: dict[tuple[int, str], Section]) -> list[ObjectEntry]:
        name = self.name(section, f"Object 0x{index:04X}")
        object_type = self.object_type(index, section, subs)
        if object_type is None:
            return []
        if object_type in (0x2, 0x7):
            domain = DataType.DOMAIN if object_type == 0x2 else None
            entry = self.entry(section, index, 0, name=name, kind="VAR", default_type=domain)
            if entry is not None and domain is not None:
                entry = entry.model_copy(update={"domain_object": True})
            return [entry] if entry else []
        kind = "ARRAY" if object_type == 0x8 else "RECORD"
        flags_key = section.get("ObjFlags")
        flags = self.integer(flags_key) if flags_key else None
        compact = section.get("CompactSubObj")
        type_key = section.get("ObjectType")
        if not subs and compact is None and type_key is not None and section.get("DataType") is not None:
            self.warn(type_key.line, type_key.name, Text(N_("object 0x{index:04X} is an {kind} without sub-objects "
                                                            "(no [{index:04X}sub0], no CompactSubObj): read as a "
                                                            "VAR, its ObjectType written back as in the file"),
                                                         index=index, kind=kind))
            entry = self.entry(section, index, 0, name=name, kind="VAR")
            return [] if entry is None else [kept_object_type(entry, type_key.value)]
        if compact is not None and (self.integer(compact, 0) or 0) != 0:
            if not subs:
                return self.with_object_keys(self.compact(index, section, compact, name, flags, aux, kind), section,
                                             _MODEL_KEYS)
            self.warn(compact.line, compact.name, Text(N_("object 0x{index:04X} has CompactSubObj and sub-object "
                                                          "sections: the sections are read"), index=index))
        number_key = section.get("SubNumber")
        read = _HEAD_KEYS
        if number_key is None:
            self.warn(section.line, "SubNumber", Text(N_("[{name}] has no SubNumber=: its {count} sub-object "
                                                         "sections are read"), name=section.name, count=len(subs)))
        elif self.integer(number_key) != len(subs):
            read = _HEAD_KEYS - {"subnumber"}  # a DCF listing some sub-objects: its SubNumber is kept as written
            self.warn(number_key.line, number_key.name, Text(N_("SubNumber={value} but object 0x{index:04X} has "
                                                                "{count} sub-objects: the {count} sections are read"),
                                                             value=number_key.value, index=index, count=len(subs)))
        entries = []
        for sub in sorted(subs):
            entry = self.entry(subs[sub], index, sub, object_name=name, kind=kind, obj_flags=flags)
            if entry is not None:
                sub_type = subs[sub].get("ObjectType")
                sub_code = OBJECT_TYPE_NAMES.get(sub_type.value.strip().lower(), _number(sub_type.value)) \
                    if sub_type is not None else 0x7
                entry = entry.model_copy(update={"domain_object": sub_code == 0x2})
                if sub_type is not None and sub_code not in (0x2, 0x7):
                    self.warn(sub_type.line, sub_type.name, Text(N_("ObjectType={value} on a sub-object: read as a "
                                                                    "VAR (CiA 306), written back as in the file"),
                                                                 value=sub_type.value), address=(index, sub))
                    entry = kept_object_type(entry, sub_type.value)
                entries.append(entry)
        if flags is not None and len({e.obj_flags for e in entries}) > 1:  # the object's own differs from a sub's
            entries = [e.model_copy(update={"object_flags": flags}) for e in entries]
        return self.with_object_keys(entries, section, read)

    @staticmethod
    def with_object_keys(entries: list[ObjectEntry], section: Section, read: set[str]) -> list[ObjectEntry]:
        """The keys of an ARRAY/RECORD's own section that were not read go on its first entry."""
        kept = {k.name: k.value for name, k in section.keys.items() if name not in read}
        if kept and entries:
            entries[0] = entries[0].model_copy(update={"object_keys": kept})
        return entries

    def compact(self, index: int, section: Section, compact: Key, name: str, flags: int | None,
                aux: dict[tuple[int, str], Section], kind: str) -> list[ObjectEntry]:
        count = self.integer(compact, 0) or 0
        if not 1 <= count <= 254:
            self.warn(compact.line, compact.name, Text(N_("CompactSubObj={count} is outside 1..254: read as {min}"),
                                                       count=count, min=min(max(count, 1), 254)))
            count = min(max(count, 1), 254)
        names = aux.get((index, "NAME"))
        values = aux.get((index, "VALUE"))
        denotations = aux.get((index, "DENOTATION"))
        file_count = _number(compact.value)  # CompactSubObj=255 (python-canopen's 0x1003): 254 read, 255 written
        written = {"DefaultValue": compact.value} if file_count != count and file_count == 255 else None
        entries = [ObjectEntry(index=index, subindex=0, name=COMPACT_SUB0_NAME, object_name=name,
                               object_type=kind, data_type=DataType.UNSIGNED8, access=Access.RO, default=count,
                               obj_flags=flags, compact=True, value_texts=written)]
        count_value = values.get("0") if values else None  # a DCF's value of sub 0, as DriveBench writes it
        if count_value is not None:
            entries[0] = entries[0].model_copy(update={"parameter_value": self.parameter_value(
                DataType.UNSIGNED8, count_value, (index, 0))})
        for sub in range(1, count + 1):
            sub_name = names.get(str(sub)) if names else None
            entry = self.entry(section, index, sub, name=sub_name.value if sub_name else f"{name}{sub}",
                               object_name=name, kind=kind, obj_flags=flags, own_values=False,
                               quiet=sub > 1)
            if entry is None:
                return [entries[0].model_copy(update={"compact": False})]
            update: dict[str, Any] = {"compact": True}
            value = values.get(str(sub)) if values else None
            if value is not None:
                update["parameter_value"] = self.parameter_value(entry.data_type, value, (index, sub))
            denotation = denotations.get(str(sub)) if denotations else None
            if denotation is not None:
                update["denotation"] = denotation.value
            entries.append(entry.model_copy(update=update))
        return entries

    def name(self, section: Section, fallback: str) -> str:
        found = section.get("ParameterName")
        if found is None or not found.value:
            self.warn(section.line, "ParameterName", Text(N_("[{name}] has no ParameterName=: named {fallback!r}"),
                                                          name=section.name, fallback=fallback))
            return fallback
        return found.value

    def parameter_value(self, data_type: DataType, key: Key, address: tuple[int, int],
                        kept: dict[str, str] | None = None) -> Value | None:
        if data_type.is_integer and "$NODEID" in key.value.upper():
            formula = self.formula(key, address)
            if formula is None and kept is not None:
                kept["ParameterValue"] = key.value
            return formula
        return self.value(data_type, key, address, kept=kept, as_key="ParameterValue")

    def formula(self, key: Key, address: tuple[int, int]) -> str | None:
        try:
            node_expr(key.value)
        except ValueError as exc:
            self.warn(key.line, key.name, Text(N_("{reason}: dropped"), reason=exc.args[0]), address=address)
            return None
        return key.value

    def value(self, data_type: DataType, key: Key, address: tuple[int, int], *, limit: str | None = None,
              quiet: bool = False, kept: dict[str, str] | None = None, as_key: str = "DefaultValue"
              ) -> Value | None:
        """A value key read as ``data_type``; where the reading changed or dropped it, its text goes to ``kept``
        (under ``limit`` or ``as_key``) so an export writes it as the file had it."""
        value, note = read_value(data_type, key.value, limit=limit)
        if (note or value is None) and kept is not None:
            kept[limit or as_key] = key.value
        if note and not quiet:
            self.warn(key.line, key.name, Text(N_("{value!r}: {note}"), value=key.value,
                                               note=note), address=address, limits=limit is not None)
        return value

    def data_type(self, section: Section, type_key: Key, quiet: bool) -> tuple[DataType, int | None]:
        """The type the model reads, and the file's code where that is another one (kept for the export)."""
        code = self.integer(type_key, what=Text(N_("read as DOMAIN")))
        if code is None:
            return DataType.DOMAIN, None
        if code in DATA_TYPE_BY_CODE:
            return DATA_TYPE_BY_CODE[code], None
        for name in (f"{code:04X}SUB1", f"{code:X}SUB1"):  # a DEFTYPE in the file: its sub 1 names the basic type
            defined = self.sections.get(name)
            base = defined.get("DefaultValue") if defined else None
            try:
                base_code = parse_int(base.value) if base else None
            except ValueError:
                base_code = None
            if defined is not None and base_code in DATA_TYPE_BY_CODE:
                base_type = DATA_TYPE_BY_CODE[base_code]
                if not quiet:
                    self.warn(type_key.line, type_key.name, Text(N_("DataType=0x{code:04X} is defined in [{name}] "
                                                                    "(sub 1): read as {value}"), code=code,
                                                                 name=defined.name, value=base_type.value))
                return base_type, code
        if not quiet:
            self.warn(type_key.line, type_key.name, Text(N_("DataType=0x{code:04X} ({type_name}) is not a CiA 301 "
                                                            "basic data type: read as DOMAIN (bytes)"), code=code,
                                                         type_name=type_name(code)))
        return DataType.DOMAIN, code

    def entry(self, section: Section, index: int, sub: int, *, name: str | None = None,
              object_name: str | None = None, kind: str, obj_flags: int | None = None,
              default_type: DataType | None = None, own_values: bool = True, quiet: bool = False
              ) -> ObjectEntry | None:
        address = (index, sub)
        named = section.get("ParameterName") if name is None else None
        name = name if name is not None else self.name(section, f"Sub-index {sub}")
        type_key = section.get("DataType")
        data_type = default_type or DataType.DOMAIN
        type_code = None
        if type_key is not None:
            data_type, type_code = self.data_type(section, type_key, quiet)
        elif default_type is None and not quiet:
            self.warn(section.line, "DataType", Text(N_("[{name}] has no DataType=: read as DOMAIN (bytes)"),
                                                     name=section.name))
        access_key = section.get("AccessType")
        access = Access.RO
        if access_key is None:
            if not quiet:
                self.warn(section.line, "AccessType", Text(N_("[{name}] has no AccessType=: read as ro"),
                                                           name=section.name))
        else:
            access, note = read_access(access_key.value)
            if note and not quiet:
                self.warn(access_key.line, access_key.name, Text(N_("{value!r} {note}"), value=access_key.value,
                                                                 note=note))
        fields: dict[str, Any] = {"index": index, "subindex": sub, "name": name, "data_type": data_type,
                                  "access": access, "object_type": kind, "object_name": object_name,
                                  "data_type_code": type_code}
        kept: dict[str, str] = {}
        if named is not None and not named.value:  # ``ParameterName=``: named so, and written back empty
            kept["ParameterName"] = ""
        factor = self.factor(section, quiet)
        if factor != 1:
            fields["factor"] = factor
        for key_name, field_name in (("Unit", "unit"), ("Description", "description"),
                                     ("Denotation", "denotation")):
            found = section.get(key_name)
            if found is not None and (own_values or field_name != "denotation"):
                fields[field_name] = found.value
        mapping = section.get("PDOMapping")
        if mapping is not None:
            fields["pdo_mappable"] = bool(self.integer(mapping, 0, what=Text(N_("read as 0 (not mappable)"))))
        flags_key = section.get("ObjFlags") if own_values else None
        fields["obj_flags"] = self.integer(flags_key) if flags_key is not None else obj_flags
        self.limits(section, data_type, factor, fields, address, quiet, kept)
        default = section.get("DefaultValue")
        if default is not None and (default.value or data_type.is_string):
            if data_type.is_integer and "$NODEID" in default.value.upper():
                fields["default_expr"] = self.formula(default, address)
                if fields["default_expr"] is None:
                    kept["DefaultValue"] = default.value
            else:
                fields["default"] = self.scaled(self.value(data_type, default, address, quiet=quiet,
                                                           kept=kept), factor)
        elif default is not None:  # ``DefaultValue=``: no default, and the key is written back as it was
            kept["DefaultValue"] = ""
        value = section.get("ParameterValue") if own_values else None
        if value is not None and (value.value or data_type.is_string):
            fields["parameter_value"] = self.parameter_value(data_type, value, address, kept)
        if kept:
            fields["value_texts"] = kept
        other = {k.name: k.value for name, k in section.keys.items() if name not in _MODEL_KEYS} if own_values \
            else {}
        factor_key = section.get("Factor")
        if factor_key is not None and factor == 1 and own_values:  # ``Factor=ERROR``, ``Factor=1``: no field holds it
            other[factor_key.name] = factor_key.value
        if other:
            fields["section_keys"] = other
        try:
            return ObjectEntry(**fields)
        except ValidationError as exc:
            self.warn(section.line, None, Text(N_("[{name}]: {value}: object skipped"), name=section.name,
                                               value=exc.errors()[0]["msg"]),
                      address=address)
            return None

    def factor(self, section: Section, quiet: bool) -> int | float:
        found = section.get("Factor")
        if found is None:
            return 1
        text = found.value.strip()
        try:
            factor: int | float = parse_int(text) if text.lstrip("+-").isdigit() else float(text)
        except ValueError:
            factor = 0
        if factor == 0 or not math.isfinite(factor):
            if not quiet:
                self.warn(found.line, found.name, Text(N_("Factor={value!r} is no usable factor: read as 1"),
                                                       value=found.value))
            return 1
        return factor

    def limits(self, section: Section, data_type: DataType, factor: int | float, fields: dict[str, Any],
               address: tuple[int, int], quiet: bool, kept: dict[str, str]) -> None:
        """LowLimit/HighLimit: unusable ones are dropped, out-of-type ones repaired, both dropped when the low
        one is above the high one (each noted; the row then says so before a write). The text of each of these
        goes to ``kept``: an export writes it as the file had it."""
        if data_type.is_string:
            for name in ("LowLimit", "HighLimit"):
                key = section.get(name)
                if key is not None and key.value.strip():
                    kept[name] = key.value
                if key is not None and key.value.strip() and not quiet:
                    self.warn(key.line, key.name, Text(N_("{value!r} ignored: a {type} has no limits"),
                                                       value=key.value, type=data_type.value),
                              address=address)
            return
        found: dict[str, Key] = {}
        for key_name, field_name in (("LowLimit", "min"), ("HighLimit", "max")):
            key = section.get(key_name)
            if key is None or not key.value or key.value.strip().lower() in ("none", "-", "n/a"):
                if key is not None and key.value:
                    kept[key_name] = key.value
                if key is not None and key.value and not quiet:
                    self.warn(key.line, key.name, Text(N_("{value!r} read as no limit"),
                                                       value=key.value), address=address, limits=True)
                continue
            raw = self.value(data_type, key, address, limit=key_name, quiet=quiet, kept=kept)
            if raw is not None:
                found[field_name] = key
                fields[field_name] = self.scaled(raw, factor)
        if "min" in fields and "max" in fields and fields["min"] > fields["max"]:
            low, high = found["min"], found["max"]
            if not quiet:
                self.warn(high.line, "LowLimit/HighLimit", Text(N_("limits dropped: LowLimit {value} > HighLimit "
                                                                   "{high} (as {type})"), value=low.value,
                                                                high=high.value, type=data_type.value),
                          address=address, limits=True)
            del fields["min"], fields["max"]
            kept |= {"LowLimit": low.value, "HighLimit": high.value}

    @staticmethod
    def scaled(raw: Value | None, factor: int | float) -> Value | None:
        if factor == 1 or raw is None or isinstance(raw, str):
            return raw
        return raw / factor

    # identity, features, the rest -----------------------------------------------------------------------
    def identity(self, info: Section, objects: list[ObjectEntry]) -> Identity:
        def number(key: str) -> int | None:
            found = info.get(key)
            value = self.integer(found, what=Text(N_("read as unknown"))) if found is not None and found.value else None
            return value if value is None or 0 <= value <= 0xFFFFFFFF else None

        order = info.get("OrderCode")
        device_type = next((o.default for o in objects if (o.index, o.subindex) == (0x1000, 0)), None)
        vendor = info.get("VendorName")
        if vendor is None:
            self.warn(info.line, "VendorName", Text(N_("[{name}] has no VendorName=: left empty"), name=info.name))
        return Identity(
            vendor_name=vendor.value if vendor is not None else "",
            vendor_id=number("VendorNumber"),
            product_name=self.product_name(info),
            product_code=number("ProductNumber"),
            revision=number("RevisionNumber"),
            order_codes=[c.strip() for c in order.value.split(",") if c.strip()] if order else [],
            device_type=device_type if isinstance(device_type, int) else None,
        )

    def product_name(self, info: Section) -> str:
        found = info.get("ProductName")
        if found is not None and found.value:
            return found.value
        file_info = self.sections.get("FILEINFO")
        candidates = [(file_info.get(k) if file_info else None) for k in ("Description", "FileName")]
        fallback = next((k.value for k in candidates if k is not None and k.value), None) or Path(
            self.source.replace("\\", "/")).name
        where = "FileInfo " + next(k.name for k in candidates if k is not None and k.value == fallback) \
            if any(k is not None and k.value == fallback for k in candidates) else Text(N_("the file name"))
        self.warn(found.line if found else info.line, "ProductName", Text(N_("[{name}] has no ProductName=: named "
                                                                             "{fallback!r} after {where}"),
                                                                          name=info.name, fallback=fallback,
                                                                          where=where))
        return fallback

    def features(self, info: Section, objects: list[ObjectEntry]) -> Features:
        indices = {o.index for o in objects}
        rates = []
        for rate in BAUD_RATES_KBIT:
            key = info.get(f"BaudRate_{rate}")
            if key is not None and self.integer(key, 0, what=Text(N_("read as 0 (not supported)"))):
                rates.append(rate)
        mapping_counts = [sum(1 for o in objects if o.index == i and o.subindex > 0)
                          for i in indices if 0x1600 <= i <= 0x17FF or 0x1A00 <= i <= 0x1BFF]
        counted = {"NrOfRXPDO": sum(1 for i in indices if 0x1400 <= i <= 0x15FF),
                   "NrOfTXPDO": sum(1 for i in indices if 0x1800 <= i <= 0x19FF)}
        pdo_counts = {}
        for name, present in counted.items():
            key = info.get(name)
            reading = Text(N_("read as {count} (the PDO objects in the file)"), count=present)
            value = self.integer(key, what=reading) if key else None
            pdo_counts[name] = present if value is None and key is not None else max(value or 0, 0)
        return Features(
            sdo_channels=max(1, sum(1 for i in indices if 0x1200 <= i <= 0x127F)),
            rpdo_count=pdo_counts["NrOfRXPDO"],
            tpdo_count=pdo_counts["NrOfTXPDO"],
            max_mapping_entries=max(mapping_counts, default=8),
            heartbeat_producer=0x1017 in indices,
            heartbeat_consumers=sum(1 for o in objects if o.index == 0x1016 and o.subindex > 0),
            node_guarding=0x100C in indices and 0x100D in indices,
            baud_rates_kbit=rates,
        )

    def notes_section(self) -> list[str]:
        section = self.sections.get("COMMENTS")
        if section is None:
            return []
        lines = sorted((k for k in section.keys.values() if re.fullmatch(r"line\d+", k.name.lower())),
                       key=lambda k: int(k.name[4:]))
        count_key = section.get("Lines")
        count = self.integer(count_key) if count_key is not None else None
        if count != len(lines):
            where = count_key.line if count_key is not None else section.line
            self.warn(where, "Lines", Text(N_("Lines={value} but [{name}] has {count} LineN keys: the {count} are "
                                              "read"), value=count_key.value if count_key else '(missing)',
                                           name=section.name, count=len(lines)))
        return [k.value for k in lines]

    def extras(self, known: set[str]) -> dict[str, dict[str, str]]:
        extra: dict[str, dict[str, str]] = {}
        for upper, section in self.sections.items():
            match = _INDEX_SECTION.match(upper)
            if upper in known or (match is not None and int(match.group(1), 16) >= 0x1000):
                continue
            extra[section.name] = {k.name: k.value for k in section.keys.values()}
        return extra


def _read_input(text_or_path: str | bytes | Path, source: str) -> str:
    if isinstance(text_or_path, Path) or (
            isinstance(text_or_path, str) and "\n" not in text_or_path
            and text_or_path.lower().endswith((".eds", ".dcf")) and Path(text_or_path).is_file()):
        path = Path(text_or_path)
        try:
            size = path.stat().st_size
            if size > MAX_EDS_BYTES:
                raise ProfileError(Text(N_("file is {size} bytes, more than the {limit} bytes an EDS may have"),
                                        size=size, limit=MAX_EDS_BYTES),
                                   source=source)
            return decode_text(path.read_bytes(), source)
        except OSError as exc:
            raise ProfileError(Text(N_("cannot read the file: {reason}"), reason=exc.strerror), source=source) from exc
    if isinstance(text_or_path, bytes):
        return decode_text(text_or_path, source)
    return text_or_path


def slug(text: str) -> str:
    """A profile id from a file name: ``../My Drive V2.EDS`` -> ``my-drive-v2``."""
    stem = Path(text.replace("\\", "/")).name
    stem = stem.rsplit(".", 1)[0] if "." in stem else stem
    cleaned = re.sub(r"[^a-z0-9_.-]+", "-", stem.lower()).strip("-._")
    return cleaned[:80] or "eds-profile"


def import_eds(text_or_path: str | bytes | Path, *, source: str) -> Profile:
    """Read an EDS or DCF (text, bytes or a path) into a Profile, quirks read as :func:`read_eds` reads them.
    Raises ProfileError(source=, line=) only for a file without a usable object dictionary."""
    return read_eds(text_or_path, source=source).profile


def read_eds(text_or_path: str | bytes | Path, *, source: str) -> ImportedEds:
    """Read an EDS or DCF into a Profile and the warnings of the readings applied (:mod:`eds_quirks`)."""
    text = _read_input(text_or_path, source)
    notes = Warnings(source)
    return read_sections(parse_ini(text, source, notes), source, notes, empty=not text.strip())


def read_sections(sections: dict[str, Section], source: str, notes: Warnings, *, empty: bool = False
                  ) -> ImportedEds:
    """EDS-shaped sections (from INI text, or built from an XDD by :mod:`drivebench.device.formats.xdd`) -> profile."""
    reader = _Reader(sections, source, notes)
    if not any(_INDEX_SECTION.match(name) and int(name[:4], 16) >= 0x1000 for name in reader.sections):
        junk = next((w.line for w in notes.items if "binary junk" in w.message), None)
        if junk is not None:
            raise reader.fail(Text(N_("binary junk (control characters) instead of EDS text, and no object "
                                       "section")), junk)
        raise reader.fail(Text(N_("no object dictionary: the file has no object section ([1000], [6040], [1018sub1] "
                                  "...)")),
                          None if empty else 1)
    info = reader.sections.get("DEVICEINFO")
    if info is None:
        reader.warn(1, None, Text(N_("no [DeviceInfo] section: vendor and product are left unknown")))
        info = Section("DeviceInfo", 1)
    objects = reader.objects()
    if not objects:
        raise reader.fail(Text(N_("no object dictionary: no object section holds a usable object")), 1)
    own = reader.sections.get(OWN_SECTION.upper())
    own_keys = {name: k.value for name, k in own.keys.items()} if own else {}
    extra = reader.extras({"DEVICEINFO", "COMMENTS", OWN_SECTION.upper(), *(n.upper() for n in OBJECT_LISTS)})
    profile_id = own_keys.get("profileid") or slug(source)
    if not re.fullmatch(r"[a-z0-9][a-z0-9_.-]*", profile_id):
        line = own.get("ProfileId").line if own and own.get("ProfileId") else 1  # type: ignore[union-attr]
        reader.warn(line, "ProfileId", Text(N_("{profile_id!r} is no profile id (a-z, 0-9, '_.-'): the file name's "
                                               "{slug!r} is used"), profile_id=profile_id, slug=slug(source)))
        profile_id = slug(source)
    try:
        profile = Profile(
            id=profile_id,
            version=own_keys.get("version", "1"),
            family=own_keys.get("family", DEFAULT_FAMILY),
            source=own_keys.get("source"),
            identity=reader.identity(info, objects),
            features=reader.features(info, objects),
            objects=objects,
            notes=reader.notes_section(),
        )
    except ValidationError as exc:
        raise reader.fail(Text(N_("not a valid profile: {value}"), value=exc.errors()[0]["msg"]), info.line) from exc
    device_extra = spelled_as({**DEVICE_INFO_DEFAULTS, **EMPTY_IDENTITY_KEYS, **EMPTY_PRODUCT_NAME}, {
        k.name: k.value for k in info.keys.values()
        if k.name.lower() not in _MAPPED_DEVICE_INFO
        or (k.name.lower() in {*EMPTY_IDENTITY_KEYS, "productname"} and not k.value)})
    device_extra = {k: v for k, v in device_extra.items() if DEVICE_INFO_DEFAULTS.get(k) != v}
    if device_extra:
        extra["DeviceInfo"] = device_extra
    extra.update(reader.unsectioned)
    comments = reader.sections.get("COMMENTS")
    if comments is not None and not profile.notes:  # ``[Comments] Lines=0``: no line, and the section kept
        extra["Comments"] = {k.name: k.value for k in comments.keys.values()}
    file_info = extra.pop(next((n for n in extra if n.upper() == "FILEINFO"), "FileInfo"), None)
    if file_info is not None:
        defaults = file_info_defaults(profile)
        named_after = "Description" if device_extra.get("ProductName") == "" else None  # kept: it names it
        kept = {k: v for k, v in spelled_as(defaults, file_info).items() if defaults.get(k) != v or k == named_after}
        if kept:
            extra["FileInfo"] = kept
    return ImportedEds(profile.model_copy(update={"extra_sections": extra}), notes.result())
