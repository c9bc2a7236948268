"""Objects added to or removed from an XDD written over its file, in that file's style: a new CANopenObject (or
CANopenSubObject) at its index in the object list, in the file's namespace, its values on a parameter where the
file keeps them there (CANopenEditor), else as attributes; a removed one out, with the parameters only it named."""

from __future__ import annotations

from lxml import etree

from drivebench.device.formats.xdd import local
from drivebench.device.formats.xdd_file import PARAMETER_HELD, XddFile
from drivebench.device.formats.xdd_tree import Address, insert, namespace_of, parameter_list, remove


def _references(element: etree._Element) -> set[str]:
    return {str(e.get("uniqueIDRef")) for e in element.iter() if isinstance(e.tag, str) and e.get("uniqueIDRef")}


def remove_objects(file: XddFile, gone: set[Address]) -> None:
    """Take out the objects and sub-objects at ``gone``, and each parameter no object of the file names then."""
    dropped: set[str] = set()
    for address in sorted(gone, key=lambda a: (a[0], -1 if a[1] is None else a[1])):
        element = file.objects.pop(address, None)
        if element is None or element.getparent() is None:
            continue
        dropped |= _references(element)
        remove(element)
    still = _references(file.listing)
    for unique_id in dropped - still:
        parameter = file.parameters.pop(unique_id, None)
        if parameter is not None:
            remove(parameter)


def _retagged(root: etree._Element, element: etree._Element, parent: etree._Element) -> etree._Element:
    """A copy of an export's element with each element in the namespace the file gives that name."""
    copy = etree.fromstring(etree.tostring(element, with_tail=False))
    for node in copy.iter():
        if isinstance(node.tag, str):
            namespace = namespace_of(root, local(node), parent)
            node.tag = f"{{{namespace}}}{local(node)}" if namespace else local(node)
    etree.cleanup_namespaces(copy)
    return copy


def _position(parent: etree._Element, tag: str, key: str, number: int) -> int:
    """Where an element numbered ``number`` (hex attribute ``key``) goes among ``parent``'s ``tag`` children."""
    for at, child in enumerate(parent):
        if isinstance(child.tag, str) and local(child) == tag:
            try:
                if int(child.get(key, ""), 16) > number:
                    return at
            except ValueError:
                continue
    return len(parent)


def _place(file: XddFile, element: etree._Element, exported: dict[str, etree._Element]) -> None:
    """The parameters an added element names, copied from the export; in a parameter-layout file its values move
    onto its parameter."""
    listing = parameter_list(file.root)
    for node in [element, *(e for e in element if isinstance(e.tag, str))]:
        reference = node.get("uniqueIDRef")
        source = exported.get(str(reference)) if reference else None
        if source is not None and listing is not None and reference not in file.parameters:
            parameter = _retagged(file.root, source, listing)
            insert(listing, len(listing), parameter)
            file.parameters[str(reference)] = parameter
        if not file.parameter_layout or node.get("dataType") is None:
            continue
        held = {a: str(node.get(a)) for a in sorted(PARAMETER_HELD) if node.get(a) is not None}
        for attribute in held:
            del node.attrib[attribute]
        for attribute, value in held.items():
            file.set_value(node, attribute, None, value)


def add_objects(file: XddFile, added: dict[Address, etree._Element], exported: dict[str, etree._Element]) -> None:
    """Put the export's elements at ``added`` into the file."""
    for address in sorted(added, key=lambda a: (a[0], -1 if a[1] is None else a[1])):
        index, sub = address
        if sub is None:
            element = _retagged(file.root, added[address], file.listing)
            insert(file.listing, _position(file.listing, "CANopenObject", "index", index), element)
            file.objects[address] = element
            for child in element:
                if isinstance(child.tag, str):
                    file.objects[(index, int(str(child.get("subIndex")), 16))] = child
            _place(file, element, exported)
            continue
        parent = file.objects.get((index, None))
        if parent is None or (index, sub) in file.objects:
            continue
        element = _retagged(file.root, added[address], parent)
        insert(parent, _position(parent, "CANopenSubObject", "subIndex", sub), element)
        file.objects[address] = element
        _place(file, element, exported)
