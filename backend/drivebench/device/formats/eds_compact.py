"""CiA 306 ``CompactSubObj`` arrays on export: an ARRAY read from one compact section is written as one again.

The compact form holds one section for the whole array (its sub-objects alike but for their names, values and
denotations) and ``[xxxxName]``/``[xxxxValue]``/``[xxxxDenotation]`` for what differs; an array that no longer fits
it (a sub-object edited on its own) is written sub by sub.
"""

from __future__ import annotations

from collections.abc import Callable

from drivebench.device.formats.eds import COMPACT_SUB0_NAME
from drivebench.device.profiles.profile import Access, ObjectEntry, Value
from drivebench.protocol.datatypes import DataType

PER_SUB = {"subindex", "name", "parameter_value", "denotation"}
"""What the sub-objects of a compact array may hold each their own."""
HEAD_KEYS_NOT_SHARED = {"ParameterName", "ObjectType", "ParameterValue", "Denotation", "ObjFlags"}


def fits_compact(entries: list[ObjectEntry]) -> bool:
    """Whether an object's entries (in sub-index order) were read compact and still fit that form: sub 0 the count
    of subs 1..N (a DCF value of its own), which are alike but for :data:`PER_SUB`."""
    head, subs = entries[0], entries[1:]
    if not subs or len(subs) > 254 or not all(e.compact and e.object_type == head.object_type != "VAR"
                                              for e in entries):
        return False
    count = ObjectEntry(index=head.index, name=COMPACT_SUB0_NAME, object_name=head.object_name,
                        object_type=head.object_type,
                        data_type=DataType.UNSIGNED8, access=Access.RO, default=len(subs), obj_flags=head.obj_flags,
                        compact=True, object_keys=head.object_keys, parameter_value=head.parameter_value,
                        value_texts=head.value_texts, object_list=head.object_list)
    if head != count or [e.subindex for e in subs] != list(range(1, len(subs) + 1)):
        return False
    shape = subs[0].model_dump(exclude=PER_SUB)
    return (shape["object_name"], shape["obj_flags"], shape["section_keys"], shape["object_keys"]) == (
        head.object_name, head.obj_flags, None, None) and all(e.model_dump(exclude=PER_SUB) == shape
                                                              for e in subs[1:])


def compact_sections(entries: list[ObjectEntry], entry_keys: Callable[[ObjectEntry], list[tuple[str, object]]],
                     value_text: Callable[[ObjectEntry], str | None]) -> list[tuple[str, list[tuple[str, object]]]]:
    """The sections of a compact array (entries that :func:`fits_compact`): ``[xxxx]`` with ``CompactSubObj``
    and the keys the sub-objects share (``entry_keys`` of sub 1), then ``[xxxxName]``, ``[xxxxValue]`` and
    ``[xxxxDenotation]`` where a sub-object has its own (``value_text``: its ParameterValue text, or None)."""
    head, subs = entries[0], entries[1:]
    object_type = "0x9" if head.object_type == "RECORD" else "0x8"  # CompactSubObj on a RECORD stays one
    count = (head.value_texts or {}).get("DefaultValue", len(subs))  # the file's CompactSubObj=255: 254 read
    keys: list[tuple[str, object]] = [("ParameterName", head.object_name), ("ObjectType", object_type),
                                      ("CompactSubObj", count)]
    keys += [(key, value) for key, value in entry_keys(subs[0]) if key not in HEAD_KEYS_NOT_SHARED]
    if head.obj_flags is not None:
        keys.append(("ObjFlags", f"0x{head.obj_flags:X}"))
    keys += list((head.object_keys or {}).items())
    index = f"{head.index:04X}"
    sections = [(index, keys)]
    names = [(e.subindex, e.name) for e in subs if e.name != f"{head.object_name}{e.subindex}"]
    values: list[tuple[int, Value]] = [(e.subindex, text) for e in entries if (text := value_text(e)) is not None]
    denotations = [(e.subindex, e.denotation) for e in subs if e.denotation is not None]
    for suffix, items in (("Name", names), ("Value", values), ("Denotation", denotations)):
        if items:
            sections.append((f"{index}{suffix}", [("NrOfEntries", len(items)),
                                                  *((str(sub), text) for sub, text in items)]))
    return sections
