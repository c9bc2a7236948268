"""CiA 306 EDS/DCF import: an electronic data sheet -> a :class:`Profile`.

The INI text is parsed here (not with configparser) so every error names the file and line.

Decisions where CiA 306 leaves room:

* Encoding: UTF-8 (with or without BOM) first, then Windows-1252, then ISO 8859-1 (CiA 306 files are 8-bit text;
  German vendors write ``°C``/``ä``, Windows tools ``€`` and curly quotes, which latin-1 would turn into control
  characters). Control characters other than tab are "binary junk" and rejected with their line.
* ``;`` starts a comment only at the beginning of a line (CiA 306 4.1); a ``;`` inside a value is part of the value.
* Integers: decimal, ``0x`` hex, or octal with a leading ``0`` (CiA 306 4.6.3). Hex limits of signed types are
  two's complement (``LowLimit=0x80000000`` of an INTEGER32 is -2147483648).
* ``$NODEID`` formulas are kept as formulas (``ObjectEntry.default_expr``; a formula ``ParameterValue`` stays a
  string) so a DCF for any node id can be written; :func:`resolve_node_expr` evaluates one.
* ``CompactSubObj`` arrays are expanded (sub 0 ``NrOfObjects``, sub n ``<ParameterName><n>`` unless ``[xxxxName]``
  names it); ``ObjectType=0x2`` (DOMAIN) becomes a VAR of data type DOMAIN.
* ``Unit``, ``Factor`` and ``Description`` (canopen's extensions) are read; with a factor, limits and defaults become
  engineering units like every other profile. Other unknown keys inside object sections are ignored.
* Sections the model has no field for (``[DummyUsage]``, ``[DeviceComissioning]``, ``[Tools]`` ...) and the
  ``[FileInfo]``/``[DeviceInfo]`` keys without a model field go to ``Profile.extra_sections`` verbatim.
* ``[DriveBench]`` (our own section, ignored by other tools) carries the profile id, family, version and source.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivebench.device.profile import Access, Features, Identity, ObjectEntry, Profile, Value
from drivebench.errors import ProfileError
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE, DataType

MAX_EDS_BYTES = 16 * 1024 * 1024
BAUD_RATES_KBIT = (10, 20, 50, 125, 250, 500, 800, 1000)
OBJECT_LISTS = ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects")
OBJECT_TYPE_CODES = {"VAR": 0x7, "ARRAY": 0x8, "RECORD": 0x9}
DEFAULT_FAMILY = "eds"
OWN_SECTION = "DriveBench"
COMPACT_SUB0_NAME = "NrOfObjects"

_INDEX_SECTION = re.compile(r"^([0-9A-F]{4})(?:SUB([0-9A-F]{1,2})|(NAME|VALUE|DENOTATION))?$")
_NODEID_EXPR = re.compile(
    r"^\s*(?:\$NODEID\s*(?:\+\s*(?P<a>[-+]?\w+))?|(?P<b>[-+]?\w+)\s*\+\s*\$NODEID)\s*$", re.IGNORECASE)
_JUNK = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
_MAPPED_DEVICE_INFO = {"vendorname", "vendornumber", "productname", "productnumber", "revisionnumber",
                       "ordercode", "nrofrxpdo", "nroftxpdo", *(f"baudrate_{b}" for b in BAUD_RATES_KBIT)}


# --- INI text with line numbers ------------------------------------------------------------------------
@dataclass
class Key:
    name: str
    value: str
    line: int


@dataclass
class Section:
    name: str
    line: int
    keys: dict[str, Key] = field(default_factory=dict)
    """Lower-case key name -> key (CiA 306 key names are case-insensitive)."""

    def get(self, key: str) -> Key | None:
        return self.keys.get(key.lower())


def decode_text(data: bytes, source: str) -> str:
    """Bytes of an EDS -> text: UTF-8, else latin-1 (see the module docstring)."""
    if len(data) > MAX_EDS_BYTES:
        raise ProfileError(f"file is {len(data)} bytes, more than the {MAX_EDS_BYTES} bytes an EDS may have",
                           source=source)
    for encoding in ("utf-8-sig", "cp1252"):
        try:
            return data.decode(encoding)
        except UnicodeDecodeError:
            continue
    return data.decode("latin-1")


def parse_ini(text: str, source: str) -> dict[str, Section]:
    """INI text -> sections keyed by upper-case name, in file order. Rejects junk and duplicates."""
    if len(text) > MAX_EDS_BYTES:
        raise ProfileError(f"file has {len(text)} characters, more than {MAX_EDS_BYTES}", source=source)
    sections: dict[str, Section] = {}
    current: Section | None = None
    # CiA 306 lines end in CR LF; str.splitlines() would also split on NEL, FF, LS... inside values.
    for number, raw in enumerate(re.split(r"\r\n|\r|\n", text), start=1):
        line = raw.strip()
        if _JUNK.search(raw):
            raise ProfileError("binary junk (control characters) instead of EDS text", source=source, line=number)
        if not line or line.startswith(";"):
            continue
        if line.startswith("["):
            if not line.endswith("]") or len(line) < 3:
                raise ProfileError(f"bad section header {line!r}", source=source, line=number)
            name = line[1:-1].strip()
            first = sections.get(name.upper())
            if first is not None:
                raise ProfileError(f"duplicate section [{name}] (first at line {first.line})",
                                   source=source, line=number)
            current = sections[name.upper()] = Section(name, number)
            continue
        if "=" not in line:
            raise ProfileError(f"expected 'key=value', a [section] or a ';' comment, got {line[:40]!r}",
                               source=source, line=number)
        if current is None:
            raise ProfileError("key outside of any section", source=source, line=number)
        key, value = (part.strip() for part in line.split("=", 1))
        if not key:
            raise ProfileError("empty key name", source=source, line=number)
        seen = current.keys.get(key.lower())
        if seen is not None:
            raise ProfileError(f"duplicate key {key!r} in [{current.name}] (first at line {seen.line})",
                               source=source, line=number)
        current.keys[key.lower()] = Key(key, value, number)
    return sections


# --- values --------------------------------------------------------------------------------------------
def parse_int(text: str) -> int:
    """CiA 306 integer: decimal, 0x hex, or octal with a leading 0. Raises ValueError."""
    cleaned = text.strip().replace(" ", "")
    sign = -1 if cleaned.startswith("-") else 1
    body = cleaned.lstrip("+-")
    if body.lower().startswith("0x"):
        return sign * int(body[2:], 16)
    if len(body) > 1 and body.startswith("0"):
        return sign * int(body[1:], 8)
    if not body.isdigit():
        raise ValueError(f"{text!r} is not a number")
    return sign * int(body)


def node_expr(text: str) -> int | None:
    """The constant of a ``$NODEID`` formula (``$NODEID+0x180`` -> 0x180), None if ``text`` is no formula."""
    if "$NODEID" not in text.upper():
        return None
    match = _NODEID_EXPR.match(text)
    if match is None:
        raise ValueError(f"{text!r} is not a formula of the form $NODEID+<number>")
    constant = match.group("a") or match.group("b")
    return parse_int(constant) if constant else 0


def resolve_node_expr(text: str, node_id: int) -> int:
    """Evaluate a ``$NODEID`` formula for one node (``$NODEID+0x180``, 5 -> 0x185)."""
    constant = node_expr(text)
    if constant is None:
        return parse_int(text)
    return constant + node_id


def parse_value(data_type: DataType, text: str) -> Value:
    """An EDS value of ``data_type`` -> raw model value. Raises ValueError naming the problem."""
    if data_type in (DataType.VISIBLE_STRING, DataType.UNICODE_STRING):
        return text
    if data_type in (DataType.OCTET_STRING, DataType.DOMAIN):
        bytes.fromhex(text)  # validates; the hex text itself is what the model stores
        return text
    if data_type.is_float:
        if text.strip().lower().startswith("0x"):  # some tools write the IEEE 754 bit pattern
            bits = parse_int(text)
            return struct.unpack("<f", bits.to_bytes(4, "little"))[0] if data_type is DataType.REAL32 else \
                struct.unpack("<d", bits.to_bytes(8, "little"))[0]
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(f"{text!r} is not a finite number")
        return value
    if data_type is DataType.BOOLEAN and text.strip().lower() in ("true", "false"):
        return int(text.strip().lower() == "true")
    value_int = parse_int(text)
    limits = data_type.raw_limits()
    assert limits is not None
    low, high = limits
    if data_type.is_signed and text.strip().lower().startswith("0x") and high < value_int <= 2 * high + 1:
        value_int -= 2 * (high + 1)  # two's complement hex (0x80000000 of an INTEGER32)
    if not low <= value_int <= high:
        raise ValueError(f"{text} does not fit {data_type.value} ({low}..{high})")
    return value_int


# --- defaults of what export writes and import need not keep ----------------------------------------------
def file_info_defaults(profile: Profile) -> dict[str, str]:
    return {"FileName": f"{profile.id}.eds", "FileVersion": "1", "FileRevision": "0", "EDSVersion": "4.0",
            "Description": profile.identity.product_name, "CreatedBy": "DriveBench"}


DEVICE_INFO_DEFAULTS = {"SimpleBootUpMaster": "0", "SimpleBootUpSlave": "1", "Granularity": "8",
                        "DynamicChannelsSupported": "0", "GroupMessaging": "0", "LSS_Supported": "0"}


# --- import --------------------------------------------------------------------------------------------
class _Reader:
    """One import: the parsed sections plus helpers that raise with file and line."""

    def __init__(self, sections: dict[str, Section], source: str) -> None:
        self.sections = sections
        self.source = source

    def fail(self, detail: str, line: int | None) -> ProfileError:
        return ProfileError(detail, source=self.source, line=line)

    def require(self, section: Section, key: str) -> Key:
        found = section.get(key)
        if found is None:
            raise self.fail(f"[{section.name}] has no {key}=", section.line)
        return found

    def integer(self, key: Key) -> int:
        try:
            return parse_int(key.value)
        except ValueError as exc:
            raise self.fail(f"{key.name}={key.value!r} is not a number", key.line) from exc

    def value(self, data_type: DataType, key: Key) -> Value:
        try:
            return parse_value(data_type, key.value)
        except (ValueError, OverflowError) as exc:
            raise self.fail(f"{key.name}={key.value!r}: {exc}", key.line) from exc

    # object lists ---------------------------------------------------------------------------------------
    def listed_indices(self) -> dict[int, Key]:
        if "MANDATORYOBJECTS" not in self.sections:
            raise self.fail("no [MandatoryObjects] section", 1)
        listed: dict[int, Key] = {}
        for list_name in OBJECT_LISTS:
            section = self.sections.get(list_name.upper())
            if section is None:
                continue
            count_key = self.require(section, "SupportedObjects")
            count = self.integer(count_key)
            numbered = [k for k in section.keys.values() if k.name.isdigit()]
            if count != len(numbered) or count < 0:
                raise self.fail(f"SupportedObjects={count} but [{section.name}] lists {len(numbered)} objects",
                                count_key.line)
            for position in range(1, count + 1):
                key = section.get(str(position))
                if key is None:
                    raise self.fail(f"[{section.name}] has no entry {position}=", section.line)
                index = self.integer(key)
                if not 0x1000 <= index <= 0xFFFF:
                    raise self.fail(f"object index 0x{index:04X} is outside 0x1000..0xFFFF", key.line)
                if index in listed:
                    raise self.fail(f"object 0x{index:04X} listed twice (first at line {listed[index].line})",
                                    key.line)
                listed[index] = key
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
            else:
                by_index[index] = section
        for index, key in listed.items():
            if index not in by_index:
                raise self.fail(f"object 0x{index:04X} is listed but has no [{index:04X}] section", key.line)
        for index, sub_sections in subs.items():
            if index not in by_index:
                first = min(sub_sections.values(), key=lambda s: s.line)
                raise self.fail(f"[{first.name}] belongs to no object section [{index:04X}]", first.line)
        entries: list[ObjectEntry] = []
        for index in sorted(i for i in by_index if i >= 0x1000):
            entries.extend(self.object(index, by_index[index], subs.get(index, {}), aux))
        return entries

    def object(self, index: int, section: Section, subs: dict[int, Section],
               aux: dict[tuple[int, str], Section]) -> list[ObjectEntry]:
        name = self.require(section, "ParameterName").value
        type_key = section.get("ObjectType")
        object_type = self.integer(type_key) if type_key else 0x7
        if object_type in (0x2, 0x7):
            if subs:
                first = min(subs.values(), key=lambda s: s.line)
                raise self.fail(f"[{first.name}]: object 0x{index:04X} is a VAR and has no sub-objects", first.line)
            domain = DataType.DOMAIN if object_type == 0x2 else None
            return [self.entry(section, index, 0, name=name, kind="VAR", default_type=domain)]
        if object_type not in (0x8, 0x9):
            assert type_key is not None
            raise self.fail(f"ObjectType=0x{object_type:X} is not supported (VAR 0x7, DOMAIN 0x2, ARRAY 0x8, "
                            "RECORD 0x9)", type_key.line)
        kind = "ARRAY" if object_type == 0x8 else "RECORD"
        flags_key = section.get("ObjFlags")
        flags = self.integer(flags_key) if flags_key else None
        compact = section.get("CompactSubObj")
        if compact is not None and self.integer(compact) != 0:
            return self.compact(index, section, compact, name, flags, aux, subs)
        number_key = self.require(section, "SubNumber")
        if self.integer(number_key) != len(subs):
            raise self.fail(f"SubNumber={number_key.value} but object 0x{index:04X} has {len(subs)} sub-objects",
                            number_key.line)
        return [self.entry(subs[sub], index, sub, object_name=name, kind=kind, obj_flags=flags)
                for sub in sorted(subs)]

    def compact(self, index: int, section: Section, compact: Key, name: str, flags: int | None,
                aux: dict[tuple[int, str], Section], subs: dict[int, Section]) -> list[ObjectEntry]:
        count = self.integer(compact)
        if subs:
            raise self.fail(f"object 0x{index:04X} has CompactSubObj and sub-object sections", compact.line)
        if not 1 <= count <= 254:
            raise self.fail(f"CompactSubObj={count} is outside 1..254", compact.line)
        names = aux.get((index, "NAME"))
        values = aux.get((index, "VALUE"))
        denotations = aux.get((index, "DENOTATION"))
        entries = [ObjectEntry(index=index, subindex=0, name=COMPACT_SUB0_NAME, object_name=name,
                               object_type="ARRAY", data_type=DataType.UNSIGNED8, access=Access.RO, default=count,
                               obj_flags=flags)]
        for sub in range(1, count + 1):
            sub_name = names.get(str(sub)) if names else None
            entry = self.entry(section, index, sub, name=sub_name.value if sub_name else f"{name}{sub}",
                               object_name=name, kind="ARRAY", obj_flags=flags, own_values=False)
            update: dict[str, Any] = {}
            value = values.get(str(sub)) if values else None
            if value is not None:
                update["parameter_value"] = self.parameter_value(entry.data_type, value)
            denotation = denotations.get(str(sub)) if denotations else None
            if denotation is not None:
                update["denotation"] = denotation.value
            entries.append(entry.model_copy(update=update))
        return entries

    def parameter_value(self, data_type: DataType, key: Key) -> Value:
        if data_type.is_integer and "$NODEID" in key.value.upper():
            self.formula(key)
            return key.value
        return self.value(data_type, key)

    def formula(self, key: Key) -> str:
        try:
            node_expr(key.value)
        except ValueError as exc:
            raise self.fail(f"{key.name}: {exc}", key.line) from exc
        return key.value

    def entry(self, section: Section, index: int, sub: int, *, name: str | None = None,
              object_name: str | None = None, kind: str, obj_flags: int | None = None,
              default_type: DataType | None = None, own_values: bool = True) -> ObjectEntry:
        name = name if name is not None else self.require(section, "ParameterName").value
        type_key = section.get("DataType")
        if type_key is None and default_type is None:
            raise self.fail(f"[{section.name}] has no DataType=", section.line)
        data_type = default_type or DataType.DOMAIN
        if type_key is not None:
            code = self.integer(type_key)
            if code not in DATA_TYPE_BY_CODE:
                raise self.fail(f"DataType=0x{code:04X} is not a CiA 301 basic data type", type_key.line)
            data_type = DATA_TYPE_BY_CODE[code]
        access_key = self.require(section, "AccessType")
        try:
            access = Access(access_key.value.strip().lower())
        except ValueError as exc:
            raise self.fail(f"AccessType={access_key.value!r} is not ro, wo, rw, rwr, rww or const",
                            access_key.line) from exc
        fields: dict[str, Any] = {"index": index, "subindex": sub, "name": name, "data_type": data_type,
                                  "access": access, "object_type": kind, "object_name": object_name}
        factor_key = section.get("Factor")
        factor: int | float = 1
        if factor_key is not None:
            try:
                factor = parse_int(factor_key.value) if factor_key.value.strip().lstrip("+-").isdigit() \
                    else float(factor_key.value)
            except ValueError as exc:
                raise self.fail(f"Factor={factor_key.value!r} is not a number", factor_key.line) from exc
            if factor == 0:
                raise self.fail("Factor=0", factor_key.line)
            fields["factor"] = factor
        for key_name, field_name in (("Unit", "unit"), ("Description", "description"),
                                     ("Denotation", "denotation")):
            found = section.get(key_name)
            if found is not None and (own_values or field_name != "denotation"):
                fields[field_name] = found.value
        mapping = section.get("PDOMapping")
        if mapping is not None:
            fields["pdo_mappable"] = bool(self.integer(mapping))
        flags_key = section.get("ObjFlags") if own_values else None
        fields["obj_flags"] = self.integer(flags_key) if flags_key is not None else obj_flags
        limits: dict[str, Key] = {}
        for key_name, field_name in (("LowLimit", "min"), ("HighLimit", "max")):
            found = section.get(key_name)
            if found is not None and found.value and not data_type.is_string:
                limits[field_name] = found
                fields[field_name] = self.scaled(self.value(data_type, found), factor)
        if "min" in fields and "max" in fields and fields["min"] > fields["max"]:
            raise self.fail(f"LowLimit {limits['min'].value} is greater than HighLimit {limits['max'].value}",
                            limits["max"].line)
        default = section.get("DefaultValue")
        if default is not None and (default.value or data_type.is_string):
            if data_type.is_integer and "$NODEID" in default.value.upper():
                fields["default_expr"] = self.formula(default)
            else:
                fields["default"] = self.scaled(self.value(data_type, default), factor)
        value = section.get("ParameterValue") if own_values else None
        if value is not None and (value.value or data_type.is_string):
            fields["parameter_value"] = self.parameter_value(data_type, value)
        try:
            return ObjectEntry(**fields)
        except ValidationError as exc:
            raise self.fail(f"[{section.name}]: {exc.errors()[0]['msg']}", section.line) from exc

    @staticmethod
    def scaled(raw: Value, factor: int | float) -> Value:
        if factor == 1 or isinstance(raw, str):
            return raw
        return raw / factor

    # identity, features, the rest -----------------------------------------------------------------------
    def identity(self, info: Section, objects: list[ObjectEntry]) -> Identity:
        def number(key: str) -> int | None:
            found = info.get(key)
            return self.integer(found) if found is not None and found.value else None

        order = info.get("OrderCode")
        device_type = next((o.default for o in objects if (o.index, o.subindex) == (0x1000, 0)), None)
        return Identity(
            vendor_name=self.require(info, "VendorName").value,
            vendor_id=number("VendorNumber"),
            product_name=self.require(info, "ProductName").value,
            product_code=number("ProductNumber"),
            revision=number("RevisionNumber"),
            order_codes=[c.strip() for c in order.value.split(",") if c.strip()] if order else [],
            device_type=device_type if isinstance(device_type, int) else None,
        )

    def features(self, info: Section, objects: list[ObjectEntry]) -> Features:
        indices = {o.index for o in objects}
        rates = []
        for rate in BAUD_RATES_KBIT:
            key = info.get(f"BaudRate_{rate}")
            if key is not None and self.integer(key):
                rates.append(rate)
        mapping_counts = [sum(1 for o in objects if o.index == i and o.subindex > 0)
                          for i in indices if 0x1600 <= i <= 0x17FF or 0x1A00 <= i <= 0x1BFF]
        rx, tx = info.get("NrOfRXPDO"), info.get("NrOfTXPDO")
        return Features(
            sdo_channels=max(1, sum(1 for i in indices if 0x1200 <= i <= 0x127F)),
            rpdo_count=self.integer(rx) if rx else 0,
            tpdo_count=self.integer(tx) if tx else 0,
            max_mapping_entries=max(mapping_counts, default=8),
            heartbeat_producer=0x1017 in indices,
            heartbeat_consumers=sum(1 for o in objects if o.index == 0x1016 and o.subindex > 0),
            node_guarding=0x100C in indices and 0x100D in indices,
            baud_rates_kbit=rates,
        )

    def notes(self) -> list[str]:
        section = self.sections.get("COMMENTS")
        if section is None:
            return []
        count = self.integer(self.require(section, "Lines"))
        return [self.require(section, f"Line{n}").value for n in range(1, count + 1)]

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
                raise ProfileError(f"file is {size} bytes, more than the {MAX_EDS_BYTES} bytes an EDS may have",
                                   source=source)
            return decode_text(path.read_bytes(), source)
        except OSError as exc:
            raise ProfileError(f"cannot read the file: {exc.strerror}", source=source) from exc
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
    """Read an EDS or DCF (text, bytes or a path) into a Profile. Raises ProfileError(source=, line=)."""
    text = _read_input(text_or_path, source)
    reader = _Reader(parse_ini(text, source), source)
    info = reader.sections.get("DEVICEINFO")
    if info is None:
        raise reader.fail("no [DeviceInfo] section", 1)
    objects = reader.objects()
    own = reader.sections.get(OWN_SECTION.upper())
    own_keys = {name: k.value for name, k in own.keys.items()} if own else {}
    extra = reader.extras({"DEVICEINFO", "COMMENTS", OWN_SECTION.upper(), *(n.upper() for n in OBJECT_LISTS)})
    try:
        profile = Profile(
            id=own_keys.get("profileid") or slug(source),
            version=own_keys.get("version", "1"),
            family=own_keys.get("family", DEFAULT_FAMILY),
            source=own_keys.get("source"),
            identity=reader.identity(info, objects),
            features=reader.features(info, objects),
            objects=objects,
            notes=reader.notes(),
        )
    except ValidationError as exc:
        line = own.get("ProfileId").line if own and own.get("ProfileId") else info.line  # type: ignore[union-attr]
        raise reader.fail(f"not a valid profile: {exc.errors()[0]['msg']}", line) from exc
    device_extra = {k.name: k.value for k in info.keys.values()
                    if k.name.lower() not in _MAPPED_DEVICE_INFO and DEVICE_INFO_DEFAULTS.get(k.name) != k.value}
    if device_extra:
        extra["DeviceInfo"] = device_extra
    file_info = extra.pop(next((n for n in extra if n.upper() == "FILEINFO"), "FileInfo"), None)
    if file_info is not None:
        defaults = file_info_defaults(profile)
        kept = {k: v for k, v in file_info.items() if defaults.get(k) != v}
        if kept:
            extra["FileInfo"] = kept
    return profile.model_copy(update={"extra_sections": extra})
