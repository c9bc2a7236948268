"""Naming and search: a ref as the user types it (``C00088``, ``P0700[1]``, ``0x2FFF.1``) to the profile's item,
the items of a query or a group, the node's groups and parameter sets."""

from __future__ import annotations

import contextlib
import re
import weakref

from drivebench.device.profiles.addressing import IndexRef, parse_ref
from drivebench.device.profiles.catalog import Catalog, Item
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.errors import UnknownParameter
from drivebench.i18n import _
from drivebench.protocol.datatypes import DataType
from drivebench.services.bus.sessions import SessionNode

_BRACKET_INDEX = re.compile(r"^\s*([A-Za-z]?\s*\d{1,5})\s*\[\s*(\d{1,3})\s*\]\s*$")


def resolve(node: SessionNode, ref: str) -> Item:
    """A profile item, or for an index the profile does not list a raw item (read as bytes).

    Indexed parameters may be written ``P0700[1]`` (= ``P0700.1``); an index of a parameter the profile lists
    only as ``.0`` is found by the catalog (:meth:`Catalog.unlisted_index`).
    """
    bracket = _BRACKET_INDEX.match(ref)
    if bracket is not None:
        ref = f"{bracket.group(1)}.{bracket.group(2)}"
    catalog = node.catalog
    if catalog is not None:
        listed = _by_ref(catalog).get(ref.strip())
        if listed is not None:  # the ref as the table shows it (0x1003.10 is subindex 10 there, not 0x10)
            return listed
        try:
            return catalog.resolve(ref)
        except UnknownParameter:
            parsed = parse_ref(ref)
            indexed = catalog.unlisted_index(parsed)
            if indexed is not None:
                return indexed
            if not isinstance(parsed, IndexRef):
                raise
    parsed = parse_ref(ref)
    if not isinstance(parsed, IndexRef):
        raise UnknownParameter(_("Node {node} has no profile: address '{ref}' by its CANopen index (0x1018.1) or "
                                 "assign a profile").format(node=node.node_id, ref=ref))
    sub = parsed.subindex or 0
    entry = ObjectEntry(name="(not in the profile)", data_type=DataType.DOMAIN, access=Access.RW,
                        index=parsed.index, subindex=sub)
    name = f"0x{parsed.index:04X}" if sub == 0 else f"0x{parsed.index:04X}.{sub}"
    return Item(name, parsed.index, sub, entry)


_REFS: weakref.WeakKeyDictionary[Catalog, dict[str, Item]] = weakref.WeakKeyDictionary()


def _by_ref(catalog: Catalog) -> dict[str, Item]:
    refs = _REFS.get(catalog)
    if refs is None:
        refs = _REFS[catalog] = {item.ref: item for item in catalog.items}
    return refs


def writable_item(catalog: Catalog | None, *refs: str) -> Item | None:
    """The first of ``refs`` the profile lists as a writable entry."""
    if catalog is None:
        return None
    for ref in refs:
        try:
            item = catalog.resolve(ref)
        except UnknownParameter:
            continue
        if item.entry.access.writable:
            return item
    return None


def items(node: SessionNode, query: str = "", group: str | None = None, parameter_set: int = 1) -> list[Item]:
    """The profile's items matching ``query``; an address the profile does not list (``0x2FFF.1``,
    ``P0700[1]``) gives the one item :func:`resolve` makes for it, so it can be read and written all the same.
    With ``parameter_set`` > 1 the codes the device keeps per set are those of that set (C0012 -> C2012)."""
    catalog = node.catalog
    if catalog is None:
        return []
    bracket = _BRACKET_INDEX.match(query)
    if bracket is not None:
        query = f"{bracket.group(1)}.{bracket.group(2)}"
    found = catalog.search(query) if query.strip() else catalog.items
    if not found and query.strip():
        with contextlib.suppress(UnknownParameter):
            found = [resolve(node, query)]
    return [catalog.in_set(item, parameter_set) for item in found if group is None or item.group == group]


def readable_items(node: SessionNode, group: str | None = None, parameter_set: int = 1) -> list[Item]:
    return [item for item in items(node, group=group, parameter_set=parameter_set) if item.entry.access.readable]


def parameter_sets(node: SessionNode) -> int:
    """How many parameter sets the node's codes have (1 without a profile)."""
    catalog = node.catalog
    return catalog.parameter_sets if catalog is not None else 1


def groups(node: SessionNode) -> list[str]:
    """Groups in the manual's order, then any others the profile's items use."""
    catalog = node.catalog
    if catalog is None:
        return []
    ordered = list(catalog.profile.groups)
    for item in catalog.items:
        if item.group not in ordered:
            ordered.append(item.group)
    return ordered
