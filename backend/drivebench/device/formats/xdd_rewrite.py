"""A regenerated XDD written over the file the profile was read from: what nobody edited stays as it was read.

As :mod:`~drivebench.device.formats.eds_rewrite` does for an EDS: the profile is compared with the one its file
gives (read again); both are written by :func:`~drivebench.device.formats.xdd_export.export_xdd` and the object and
parameter attributes whose text differs are the edits. Only those change in the file's own XML tree, each where the
file holds it: an attribute of the CANopenObject/CANopenSubObject (``defaultValue="..."``), or, where the object
refers to a parameter (``uniqueIDRef``) that holds it as CANopenEditor writes them, that parameter's
``defaultValue``/``actualValue`` element, ``allowedValues`` range, ``label``, ``denotation``, ``access``,
``description`` and ``property`` elements; a number in the style of the text it replaces (hex, digit count, case).
A value the file does not have yet goes where the file keeps that object's values. An added object goes into the
object list at its index (its values on a parameter too where the file's objects keep them there), a removed one
out, with the parameters only it referred to. An unedited profile gives the file back byte for byte; an edited
one is the file's tree, its XML declaration, comments and encoding as they were. A change outside the objects
(identity, features, file information) is written by the full writer, which has a place for each of them.
"""

from __future__ import annotations

from collections.abc import Callable

from lxml import etree

from drivebench.device.formats.xdd import local, read_xdd
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.device.formats.xdd_file import XddFile
from drivebench.device.formats.xdd_objects import add_objects, remove_objects
from drivebench.device.formats.xdd_tree import Address, communication_body, object_list, objects, parameters, written
from drivebench.device.profiles.profile import Profile

_IGNORED = {"uniqueIDRef"}


def _facts(content: bytes) -> tuple[dict[Address, etree._Element], dict[str, etree._Element]]:
    root = etree.fromstring(content)
    body = communication_body(root)
    listing = object_list(body) if body is not None else None
    return (objects(listing) if listing is not None else {}), parameters(root)


def _attributes(element: etree._Element | None) -> dict[str, str]:
    return {} if element is None else {str(k): str(v) for k, v in element.attrib.items()
                                       if k not in _IGNORED and k not in ("index", "subIndex")}


def _parameter_facts(element: etree._Element | None, params: dict[str, etree._Element]) -> dict[str, str]:
    """What an export's parameter says beyond the object attributes: description and properties."""
    parameter = params.get(str(element.get("uniqueIDRef"))) if element is not None else None
    if parameter is None:
        return {}
    facts = {f"property:{p.get('name')}": str(p.get("value")) for p in parameter if local(p) == "property"}
    description = next((e for e in parameter if local(e) == "description"), None)
    if description is not None:
        facts["description"] = description.text or ""
    return facts


def rewrite_xdd(profile: Profile, original: bytes, source: str,
                finish: Callable[[etree._Element], None] | None = None) -> bytes:
    """``profile`` as an XDD written over ``original`` (the XDD/XDC it was read from): only its edits change;
    ``finish`` changes the tree further before it is written (an XDC's ``deviceCommissioning``)."""
    baseline = read_xdd(original, source=source).profile.model_copy(update={"id": profile.id})
    if baseline == profile and finish is None:
        return original
    outside = {"id", "objects"}
    if baseline.model_dump(exclude=outside) != profile.model_dump(exclude=outside):
        return export_xdd(profile)  # identity, features or file information: the full writer's places
    (before, before_params), (after, after_params) = _facts(export_xdd(baseline)), _facts(export_xdd(profile))
    changes = []
    for address in before.keys() & after.keys():
        old, new = _attributes(before[address]), _attributes(after[address])
        changes += [(address, a, old.get(a), new.get(a)) for a in sorted(old.keys() | new.keys())
                    if old.get(a) != new.get(a)]
        old_facts = _parameter_facts(before[address], before_params)
        new_facts = _parameter_facts(after[address], after_params)
        changes += [(address, f, None, new_facts.get(f)) for f in sorted(old_facts.keys() | new_facts.keys())
                    if old_facts.get(f) != new_facts.get(f)]
    if not changes and before.keys() == after.keys() and finish is None:
        return original
    file = XddFile(original, source)
    remove_objects(file, before.keys() - after.keys())
    for address, name, old_text, new_text in sorted(changes, key=lambda c: (c[0][0], -1 if c[0][1] is None
                                                                             else c[0][1], c[1])):
        target = file.objects.get(address)
        if target is None:
            continue
        unique_id = after[address].get("uniqueIDRef")
        if name == "description" or name.startswith("property:"):
            file.set_parameter_fact(target, name, new_text, unique_id)
        else:
            file.set_value(target, name, old_text, new_text, unique_id)
    add_objects(file, {a: after[a] for a in after.keys() - before.keys()}, after_params)
    if finish is not None:
        finish(file.root)
    return written(original, file.root, file.snapshot)
