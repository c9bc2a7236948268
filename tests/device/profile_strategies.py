"""Hypothesis strategies for profiles as an EDS/DCF/XDD import can give them: every field the model holds for an
imported file (DOMAIN objects, CompactSubObj arrays, kept keys of object sections, DCF values and denotations)."""

from __future__ import annotations

from hypothesis import strategies as st

from drivebench.device.formats.eds import BAUD_RATES_KBIT
from drivebench.device.profiles.profile import Access, Identity, ObjectEntry, Profile
from drivebench.protocol.datatypes import DataType

TEXT = st.text(st.characters(min_codepoint=32, max_codepoint=0x17F, blacklist_characters="\x7f;"),
                min_size=1, max_size=20).map(str.strip).filter(bool)
_TYPES = [t for t in DataType]
_SECTION_NAME = st.from_regex(r"\A[A-Z][A-Za-z_]{2,12}\Z").filter(
    lambda n: n.upper() not in {"FILEINFO", "DEVICEINFO", "COMMENTS", "DRIVEBENCH", "DEVICECOMISSIONING",
                                "MANDATORYOBJECTS", "OPTIONALOBJECTS", "MANUFACTUREROBJECTS"}
    and not all(c in "0123456789ABCDEF" for c in n.upper()[:4]))

_KEPT_KEYS = st.dictionaries(st.from_regex(r"\A(Upload|Download|Storage|Vendor)[A-Za-z]{1,6}\Z"), TEXT, min_size=1,
                             max_size=2).map(lambda keys: {k: v for k, v in {n.lower(): (n, v) for n, v in
                                                                             keys.items()}.values()})
"""Keys of an object's section the model has no field for (UploadFile, StorageLocation, vendor keys)."""


@st.composite
def raw_value(draw: st.DrawFn, data_type: DataType, factor: int) -> int | float | str:
    if data_type in (DataType.VISIBLE_STRING, DataType.UNICODE_STRING):
        return draw(st.one_of(st.just(""), TEXT))
    if data_type in (DataType.OCTET_STRING, DataType.DOMAIN):
        return draw(st.binary(max_size=8)).hex().upper()
    if data_type.is_float:
        return draw(st.floats(allow_nan=False, allow_infinity=False, width=32 if data_type is DataType.REAL32
                              else 64))
    low, high = data_type.raw_limits()  # type: ignore[misc]
    if factor != 1:  # a scaled value is a float (10.2 A): exact for raws up to 2**53, as every manual's value is
        low, high = max(low, -(2**53)), min(high, 2**53)
    raw = draw(st.integers(low, high))
    return raw if factor == 1 else raw / factor


@st.composite
def _entry(draw: st.DrawFn, index: int, sub: int, kind: str, object_name: str | None) -> ObjectEntry:
    data_type = draw(st.sampled_from(_TYPES))
    factor = draw(st.sampled_from([1, 1, 10, 100])) if data_type.is_integer else 1
    fields: dict = {"index": index, "subindex": sub, "object_type": kind, "object_name": object_name,
                    "name": draw(TEXT), "data_type": data_type, "factor": factor,
                    "access": draw(st.sampled_from(list(Access))), "pdo_mappable": draw(st.booleans()),
                    "obj_flags": draw(st.none() | st.integers(0, 3)), "denotation": draw(st.none() | TEXT),
                    "unit": draw(st.none() | TEXT), "description": draw(st.none() | TEXT),
                    "section_keys": draw(st.none() | _KEPT_KEYS),
                    "domain_object": kind == "VAR" and draw(st.booleans())}
    if not data_type.is_string and draw(st.booleans()):
        low, high = sorted([draw(raw_value(data_type, factor)), draw(raw_value(data_type, factor))])
        fields |= {"min": low, "max": high}
    formula = data_type in (DataType.UNSIGNED32, DataType.UNSIGNED16) and factor == 1 and draw(st.booleans())
    if formula:
        fields["default_expr"] = f"$NODEID+0x{draw(st.integers(0, 0x7FF)):X}"
        fields["parameter_value"] = draw(st.none() | st.just("$NODEID+0x180"))
    else:
        fields["default"] = draw(st.none() | raw_value(data_type, factor))
        fields["parameter_value"] = draw(st.none() | raw_value(data_type, 1))
    return ObjectEntry(**fields)


@st.composite
def compact_array(draw: st.DrawFn, index: int, name: str) -> list[ObjectEntry]:
    """A CiA 306 CompactSubObj array as the import reads one: sub 0 the count, subs 1..N alike but for their
    names, ParameterValue and Denotation."""
    count = draw(st.integers(1, 5))
    shape = draw(_entry(index, 1, "ARRAY", name)).model_copy(update={"section_keys": None, "compact": True})
    head = ObjectEntry(index=index, name="NrOfObjects", object_name=name, object_type="ARRAY", compact=True,
                       data_type=DataType.UNSIGNED8, access=Access.RO, default=count, obj_flags=shape.obj_flags,
                       parameter_value=draw(st.none() | st.integers(0, 255)))
    subs = [shape.model_copy(update={
        "subindex": sub, "name": draw(st.just(f"{name}{sub}") | TEXT), "denotation": draw(st.none() | TEXT),
        "parameter_value": draw(st.none() | raw_value(shape.data_type, 1))}) for sub in range(1, count + 1)]
    return [head, *subs]


@st.composite
def profiles(draw: st.DrawFn) -> Profile:
    device_type = draw(st.integers(0, 0xFFFFFFFF))
    objects = [
        ObjectEntry(index=0x1000, name="Device type", data_type=DataType.UNSIGNED32, access=Access.RO,
                    default=device_type),
        ObjectEntry(index=0x1001, name="Error register", data_type=DataType.UNSIGNED8, access=Access.RO),
        ObjectEntry(index=0x1018, name="Highest sub-index supported", object_name="Identity object",
                    object_type="RECORD", data_type=DataType.UNSIGNED8, access=Access.RO, default=1),
        ObjectEntry(index=0x1018, subindex=1, name="Vendor-ID", object_name="Identity object",
                    object_type="RECORD", data_type=DataType.UNSIGNED32, access=Access.RO, default=1),
    ]
    indices = draw(st.lists(st.integers(0x1002, 0x9FFF).filter(lambda i: i != 0x1018), max_size=6, unique=True))
    for index in indices:
        kind = draw(st.sampled_from(["VAR", "ARRAY", "RECORD"]))
        if kind == "VAR":
            objects.append(draw(_entry(index, 0, "VAR", None)))
            continue
        name = draw(TEXT)
        if kind == "ARRAY" and draw(st.booleans()):
            entries = draw(compact_array(index, name))
        else:
            subs = draw(st.lists(st.integers(0, 255), min_size=1, max_size=4, unique=True))
            entries = [draw(_entry(index, sub, kind, name)) for sub in sorted(subs)]
        kept = draw(st.none() | _KEPT_KEYS)
        objects += [entries[0].model_copy(update={"object_keys": kept}), *entries[1:]]
    extra = draw(st.dictionaries(_SECTION_NAME, st.dictionaries(
        st.from_regex(r"\A[A-Za-z][A-Za-z0-9_]{0,8}\Z"), TEXT, max_size=3), max_size=2))
    extra = {name: {k: v for k, v in {key.lower(): (key, v) for key, v in keys.items()}.values()}
             for name, keys in {n.upper(): (n, k) for n, k in extra.items()}.values()}
    return Profile(
        id=draw(st.from_regex(r"\A[a-z0-9][a-z0-9_.-]{0,20}\Z")),
        family=draw(st.from_regex(r"\A[a-z][a-z0-9-]{0,10}\Z")),
        version=draw(st.from_regex(r"\A[0-9]{1,3}\Z")),
        source=draw(st.none() | TEXT),
        identity=Identity(vendor_name=draw(TEXT), vendor_id=draw(st.none() | st.integers(0, 0xFFFFFFFF)),
                          product_name=draw(TEXT), product_code=draw(st.none() | st.integers(0, 0xFFFFFFFF)),
                          revision=draw(st.none() | st.integers(0, 0xFFFFFFFF)),
                          order_codes=draw(st.lists(TEXT.filter(lambda t: "," not in t), max_size=2)),
                          device_type=device_type),
        objects=objects,
        notes=draw(st.lists(TEXT, max_size=3)),
        extra_sections=extra,
    ).model_copy(update={"features": Profile.model_fields["features"].default_factory().model_copy(  # type: ignore[misc]
        update={"baud_rates_kbit": sorted(draw(st.sets(st.sampled_from(BAUD_RATES_KBIT)))),
                "rpdo_count": draw(st.integers(0, 512)), "tpdo_count": draw(st.integers(0, 512))})})
