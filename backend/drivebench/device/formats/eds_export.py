"""CiA 306 EDS/DCF export: a :class:`Profile` -> EDS or DCF text that :func:`import_eds` reads back unchanged.

canopen's ``export_od`` is not used: it drops ObjFlags, Denotation, comments and unknown sections (libs.md §3).
Vendor parameters (Lenze codes, Siemens P/r parameters) become manufacturer objects at the index the family's
addressing rule gives, named ``C00088: Rated motor current``. Values are written raw (``raw = value * factor``);
``Factor``/``Unit``/``Description`` are written as canopen's extension keys so the import restores engineering units.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

from drivebench.device.formats.dcf_patch import patch_dcf
from drivebench.device.formats.eds import (
    BAUD_RATES_KBIT,
    DEVICE_INFO_DEFAULTS,
    MANDATORY_OBJECTS,
    OBJECT_TYPE_CODES,
    OWN_SECTION,
    decode_text,
    file_info_defaults,
    node_expr,
    range_object_list,
    resolve_node_expr,
)
from drivebench.device.formats.eds_compact import compact_sections, fits_compact
from drivebench.device.profiles.addressing import code_to_index, format_code
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.profile import Access, CodeAddressing, ObjectEntry, Parameter, Profile, Value
from drivebench.errors import ProfileError, UnknownParameter
from drivebench.i18n import _
from drivebench.protocol.datatypes import DataType

MANDATORY = MANDATORY_OBJECTS
Address = tuple[int, int]


def _one_line(text: str) -> str:
    return " ".join(str(text).split("\n")).replace("\r", " ")


def _format(data_type: DataType, raw: Value) -> str:
    """A raw value as EDS text: unsigned 24..64-bit in hex, other integers decimal, floats exact."""
    if isinstance(raw, str):
        return _one_line(raw)
    if data_type.is_float:
        return repr(float(raw))
    if data_type.is_integer:
        number = round(raw)
        size = data_type.size or 0
        if not data_type.is_signed and size >= 3 and number >= 0:
            return f"0x{number:0{size * 2}X}"
        return str(number)
    return _one_line(str(raw))


def _raw(entry: ObjectEntry, value: Value) -> Value:
    """Engineering units -> raw, as the device holds it."""
    if isinstance(value, str) or entry.factor == 1:
        return value
    if entry.data_type.is_integer:
        return round(value * entry.factor)
    return value * entry.factor


def _parameter_objects(profile: Profile, taken: set[int]) -> list[ObjectEntry]:
    """Vendor parameters as manufacturer objects at their CANopen index (parameter sets 2..4 included)."""
    if not profile.parameters:
        return []
    try:
        catalog = Catalog(profile)
    except UnknownParameter as exc:
        raise ProfileError(exc.detail, source=profile.id) from exc
    by_index: dict[int, dict[int, tuple[Parameter, str, str]]] = {}
    for item in catalog.items:
        par = item.entry
        if not isinstance(par, Parameter):
            continue
        places = [(item.index, item.subindex, par.code, "")]
        addressing = profile.addressing
        if isinstance(addressing, CodeAddressing) and par.index is None:
            number = int("".join(ch for ch in par.code if ch.isdigit()))
            for pset in range(2, par.parameter_sets + 1):
                set_number = number + addressing.set_offset * (pset - 1)
                try:
                    index, sub = code_to_index(addressing, set_number, par.subcode)
                except UnknownParameter:
                    continue
                places.append((index, sub, format_code(addressing, "C", set_number), f" (parameter set {pset})"))
        for index, sub, code, suffix in places:
            if index not in taken and 0x2000 <= index <= 0x5FFF:
                by_index.setdefault(index, {}).setdefault(sub, (par, code, suffix))
    entries: list[ObjectEntry] = []
    for index, members in sorted(by_index.items()):
        subs = sorted(members)
        record = len(subs) > 1 or subs[0] != 0
        first_par, first_code, first_suffix = members[subs[0]]
        object_name = f"{first_code}: {first_par.name}{first_suffix}"
        if record and subs[0] != 0:
            entries.append(ObjectEntry(index=index, subindex=0, name="Highest sub-index supported",
                                       object_name=object_name, object_type="RECORD",
                                       data_type=DataType.UNSIGNED8, access=Access.RO, default=subs[-1]))
        for sub in subs:
            par, code, suffix = members[sub]
            sep = "." if code[:1] in ("P", "r") else "/"
            ref = f"{code}{sep}{sub}" if record else code
            fields = par.model_dump(include={"data_type", "access", "unit", "factor", "min", "max", "default",
                                             "pdo_mappable", "description", "reset_required", "group",
                                             "selection", "bits"})
            entries.append(ObjectEntry(index=index, subindex=sub, name=f"{ref}: {par.subcode_name or par.name}"
                                       f"{suffix}", object_name=object_name if record else None,
                                       object_type="RECORD" if record else "VAR", code=par.code, **fields))
    return entries


def _mandatory_objects(profile: Profile, present: set[int]) -> list[ObjectEntry]:
    """0x1000, 0x1001 and 0x1018 from the identity where the profile does not list them (CiA 301 mandatory)."""
    ident = profile.identity
    added: list[ObjectEntry] = []
    if 0x1000 not in present:
        added.append(ObjectEntry(index=0x1000, name="Device type", data_type=DataType.UNSIGNED32,
                                 access=Access.RO, default=ident.device_type or 0))
    if 0x1001 not in present:
        added.append(ObjectEntry(index=0x1001, name="Error register", data_type=DataType.UNSIGNED8,
                                 access=Access.RO, default=0))
    if 0x1018 not in present:
        subs = [("Vendor-ID", ident.vendor_id), ("Product code", ident.product_code),
                ("Revision number", ident.revision), ("Serial number", None)]
        added.append(ObjectEntry(index=0x1018, subindex=0, name="Highest sub-index supported",
                                 object_name="Identity object", object_type="RECORD",
                                 data_type=DataType.UNSIGNED8, access=Access.RO, default=len(subs)))
        for sub, (name, value) in enumerate(subs, start=1):
            added.append(ObjectEntry(index=0x1018, subindex=sub, name=name, object_name="Identity object",
                                     object_type="RECORD", data_type=DataType.UNSIGNED32, access=Access.RO,
                                     default=value if value is not None else 0))
    return added


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def section(self, name: str, keys: Iterable[tuple[str, object]]) -> None:
        if self.lines:
            self.lines.append("")
        self.lines.append(f"[{name}]")
        self.lines.extend(f"{key}={_one_line(str(value))}" for key, value in keys)

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _extra(profile: Profile, name: str) -> dict[str, str]:
    for section, keys in profile.extra_sections.items():
        if section.lower() == name.lower():
            return keys
    return {}


def export_value_text(entry: ObjectEntry, value: Value | None) -> dict[str, str]:
    """The value keys of an object as EDS text (raw): DefaultValue, LowLimit, HighLimit, ParameterValue,
    Denotation, where the object has them."""
    texts: dict[str, str] = {}
    if entry.default_expr is not None:
        texts["DefaultValue"] = entry.default_expr
    elif entry.default is not None:
        texts["DefaultValue"] = _format(entry.data_type, _raw(entry, entry.default))
    if entry.min is not None and not entry.data_type.is_string:
        texts["LowLimit"] = _format(entry.data_type, _raw(entry, entry.min))
    if entry.max is not None and not entry.data_type.is_string:
        texts["HighLimit"] = _format(entry.data_type, _raw(entry, entry.max))
    if value is not None:
        texts["ParameterValue"] = _format(entry.data_type, value)
    if entry.denotation is not None:
        texts["Denotation"] = _one_line(entry.denotation)
    for key, text in (entry.value_texts or {}).items():  # as the file had it (the import read it with a change)
        if key != "ParameterValue" or value is entry.parameter_value:
            texts[key] = _one_line(text)
    return texts


def written_name(entry: ObjectEntry) -> str:
    """The ParameterName of an entry's own section: empty where the file left it so (``ParameterName=``)."""
    return (entry.value_texts or {}).get("ParameterName", entry.name)


def object_type_text(entry: ObjectEntry) -> str:
    """The ObjectType of an entry's own section: the file's where it read the entry as a VAR otherwise."""
    return (entry.value_texts or {}).get("ObjectType") or ("0x2" if entry.domain_object else "0x7")


def _entry_keys(entry: ObjectEntry, *, with_flags: bool, value: Value | None) -> list[tuple[str, object]]:
    keys: list[tuple[str, object]] = [("ParameterName", written_name(entry)), ("ObjectType", object_type_text(entry))]
    code = entry.data_type_code if entry.data_type_code is not None else entry.data_type.code
    keys += [("DataType", f"0x{code:04X}"),
             ("AccessType", entry.access.value)]
    texts = export_value_text(entry, value)
    if "DefaultValue" in texts:
        keys.append(("DefaultValue", texts["DefaultValue"]))
    keys.append(("PDOMapping", int(entry.pdo_mappable)))
    keys += [(key, texts[key]) for key in ("LowLimit", "HighLimit") if key in texts]
    if with_flags and entry.obj_flags is not None and entry.obj_flags != entry.object_flags:
        keys.append(("ObjFlags", f"0x{entry.obj_flags:X}"))
    keys += [(key, texts[key]) for key in ("ParameterValue", "Denotation") if key in texts]
    keys += list((entry.section_keys or {}).items())
    if entry.factor != 1:
        keys.append(("Factor", entry.factor))
    if entry.unit is not None:
        keys.append(("Unit", entry.unit))
    if entry.description is not None:
        keys.append(("Description", entry.description))
    return keys


def _patched_dcf(profile: Profile, original: bytes, node_id: int | None, values: Mapping[Address, Value],
                 baud_kbit: int | None) -> str:
    by_address = {(o.index, o.subindex): o for o in profile.objects}
    texts: dict[Address, str] = {}
    for address, value in values.items():
        entry = by_address.get(address)
        if entry is None:
            raise UnknownParameter(_not_an_object(address, profile))
        texts[address] = _format(entry.data_type, value)
    commissioning = {key: str(value) for key, value in (("NodeID", node_id), ("Baudrate", baud_kbit))
                     if value is not None}
    patched = patch_dcf(original, profile.id, texts, commissioning=commissioning)
    return decode_text(patched, profile.id)


def objects_by_index(profile: Profile) -> dict[int, list[ObjectEntry]]:
    """Every object an export writes, by index in index order: the profile's, the CiA 301 mandatory ones it lacks
    and its vendor parameters as manufacturer objects."""
    by_index: dict[int, list[ObjectEntry]] = {}
    for entry in sorted(eds_objects(profile), key=lambda o: (o.index, o.subindex)):
        by_index.setdefault(entry.index, []).append(entry)
    return by_index


def node_value(entry: ObjectEntry, values: Mapping[Address, Value], node_id: int | None, dcf: bool
               ) -> Value | None:
    """The value a DCF/XDC gives an object: the one asked for, else its ParameterValue; for a node id, a
    ``$NODEID`` formula's value."""
    value = values.get((entry.index, entry.subindex), entry.parameter_value)
    if dcf and node_id is not None:
        if value is None and entry.default_expr is not None:
            return resolve_node_expr(entry.default_expr, node_id)
        if isinstance(value, str) and entry.data_type.is_integer and node_expr(value) is not None:
            return resolve_node_expr(value, node_id)
    return value


def eds_objects(profile: Profile) -> list[ObjectEntry]:
    """Every entry the EDS of ``profile`` lists: its objects, the CiA 301 mandatory ones it lacks, and its vendor
    parameters at their indices (Lenze parameter sets 2..4 and the sub 0 of coded arrays included)."""
    objects = list(profile.objects)
    present = {o.index for o in objects}
    return objects + _mandatory_objects(profile, present) + _parameter_objects(profile, present)


def _object_sections(index: int, entries: list[ObjectEntry], parameter_value: Callable[[ObjectEntry], Value | None]
                     ) -> list[tuple[str, list[tuple[str, object]]]]:
    """The sections of one object: ``[xxxx]`` of a VAR; ``[xxxx]`` and ``[xxxxsubN]`` of an ARRAY/RECORD, or
    one compact section where it was read so (:mod:`drivebench.device.formats.eds_compact`)."""
    first = entries[0]
    if len(entries) == 1 and first.subindex == 0 and first.object_type == "VAR":
        return [(f"{index:04X}", _entry_keys(first, with_flags=True, value=parameter_value(first)))]
    if fits_compact(entries):
        def value_text(entry: ObjectEntry) -> str | None:
            return export_value_text(entry, parameter_value(entry)).get("ParameterValue")

        return compact_sections(entries, lambda e: _entry_keys(e, with_flags=False, value=None), value_text)
    flags = {e.obj_flags for e in entries}
    shared_flags = first.object_flags if first.object_flags is not None else flags.pop() if len(flags) == 1 else None
    kind = first.object_type if first.object_type != "VAR" else "RECORD"
    kept = dict(first.object_keys or {})
    number = kept.pop("SubNumber", len(entries))  # a DCF listing some sub-objects keeps its SubNumber
    head: list[tuple[str, object]] = [("ParameterName", first.object_name or first.name),
                                      ("ObjectType", f"0x{OBJECT_TYPE_CODES[kind]:X}"), ("SubNumber", number)]
    if shared_flags is not None:
        head.append(("ObjFlags", f"0x{shared_flags:X}"))
    head += list(kept.items())
    return [(f"{index:04X}", head), *((f"{index:04X}sub{entry.subindex:X}", _entry_keys(
        entry, with_flags=shared_flags is None or first.object_flags is not None, value=parameter_value(entry)))
        for entry in entries)]


def export_eds(profile: Profile, *, node_id: int | None = None, values: Mapping[Address, Value] | None = None,
               dcf: bool = False, baud_kbit: int | None = None, original: bytes | None = None) -> str:
    """Write ``profile`` as an EDS, or with ``dcf=True`` a DCF for ``node_id``.

    ``values`` are raw values (as read from the device or stored in a parameter set) by (index, subindex); they
    become ``ParameterValue``. In a DCF for a node id, ``$NODEID`` formulas get their value for that node.
    With ``original`` (the bytes of the EDS/DCF the profile was read from) a DCF is that file with only the values
    and ``[DeviceComissioning]`` changed (:func:`drivebench.device.formats.dcf_patch.patch_dcf`): layout, comments and
    keys the model has no field for stay.
    """
    if node_id is not None and not 1 <= node_id <= 127:
        raise ProfileError(_("node id {node} is outside 1..127").format(node=node_id), source=profile.id)
    if original is not None and dcf:
        return _patched_dcf(profile, original, node_id, values or {}, baud_kbit)
    by_index = objects_by_index(profile)
    addresses = {(o.index, o.subindex) for entries in by_index.values() for o in entries}
    for address in (values or {}):
        if address not in addresses:
            raise UnknownParameter(_not_an_object(address, profile))

    def parameter_value(entry: ObjectEntry) -> Value | None:
        return node_value(entry, values or {}, node_id, dcf)

    out = _Writer()
    ident, features = profile.identity, profile.features
    out.section("FileInfo", {**file_info_defaults(profile), **_extra(profile, "FileInfo")}.items())
    device_info: dict[str, object] = {"VendorName": ident.vendor_name}
    if ident.vendor_id is not None:
        device_info["VendorNumber"] = f"0x{ident.vendor_id:08X}"
    device_info["ProductName"] = ident.product_name
    if ident.product_code is not None:
        device_info["ProductNumber"] = f"0x{ident.product_code:08X}"
    if ident.revision is not None:
        device_info["RevisionNumber"] = f"0x{ident.revision:08X}"
    if ident.order_codes:
        device_info["OrderCode"] = ", ".join(ident.order_codes)
    for rate in BAUD_RATES_KBIT:
        device_info[f"BaudRate_{rate}"] = int(rate in features.baud_rates_kbit)
    device_info |= {"NrOfRXPDO": features.rpdo_count, "NrOfTXPDO": features.tpdo_count}
    device_info |= {key: value for key, value in {**DEVICE_INFO_DEFAULTS, **_extra(profile, "DeviceInfo")}.items()
                    if value != "" or key not in device_info or key == "ProductName"}  # an empty identity key
    # where the model has none; ``ProductName=``: the model's is the name the import gave it
    out.section("DeviceInfo", device_info.items())
    if profile.notes:
        out.section("Comments", [("Lines", len(profile.notes)),
                                 *((f"Line{n}", note) for n, note in enumerate(profile.notes, start=1))])
    elif _extra(profile, "Comments"):
        out.section("Comments", _extra(profile, "Comments").items())
    own: list[tuple[str, object]] = [("ProfileId", profile.id), ("Family", profile.family),
                                     ("Version", profile.version)]
    if profile.source is not None:
        own.append(("Source", profile.source))
    out.section(OWN_SECTION, own)
    commissioning = dict(_extra(profile, "DeviceComissioning"))
    if node_id is not None:
        commissioning["NodeID"] = str(node_id)
    if baud_kbit is not None:
        commissioning["Baudrate"] = str(baud_kbit)
    if dcf or commissioning:
        out.section("DeviceComissioning", commissioning.items())
    for list_name in ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects"):
        listed = sorted({i for i, es in by_index.items() if (es[0].object_list or range_object_list(i)) == list_name}
                        | {int(index, 16) for index in _extra(profile, list_name)})  # listed, without a section
        out.section(list_name, [("SupportedObjects", len(listed)),
                                *((str(n), f"0x{i:04X}") for n, i in enumerate(listed, start=1))])
    for index, entries in by_index.items():
        for section_name, section_keys in _object_sections(index, entries, parameter_value):
            out.section(section_name, section_keys)
    handled = {"fileinfo", "deviceinfo", "devicecomissioning", "comments", OWN_SECTION.lower(),
               "mandatoryobjects", "optionalobjects", "manufacturerobjects"}
    for name, keys in profile.extra_sections.items():
        if name.lower() not in handled:
            out.section(name, keys.items())
    return out.text()


def _not_an_object(address: Address, profile: Profile) -> str:
    return _("{object} is not an object of '{profile}'").format(object=f"0x{address[0]:04X}sub{address[1]}",
                                                                 profile=profile.id)
