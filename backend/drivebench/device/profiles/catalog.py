"""One profile, flattened into addressable items: what a node's parameter table shows and what a ref resolves to."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from functools import cached_property

from drivebench.device.profiles.addressing import (
    CodeRef,
    IndexRef,
    code_parameter_set,
    code_to_index,
    format_code,
    index_to_code,
    parse_ref,
)
from drivebench.device.profiles.profile import Access, CodeAddressing, Entry, ObjectEntry, Parameter, Profile
from drivebench.errors import UnknownParameter
from drivebench.i18n import _
from drivebench.protocol.datatypes import DataType


@dataclass(frozen=True)
class Item:
    """One value on the device: where it lives on the bus and what the profile says about it."""

    ref: str
    """Canonical name: ``C00088``, ``C00118/3``, ``P2040``, ``r2054.3`` or ``0x1017`` / ``0x1018.1``."""
    index: int
    subindex: int
    entry: Entry
    parameter_set: int = 1

    @property
    def name(self) -> str:
        return self.name_for("en")

    def name_for(self, language: str) -> str:
        """The name as the manual in ``language`` prints it: the profile's ``name_de`` in German where it gives one,
        else the name the profile was written with (vendor names are never translated by the tool)."""
        entry = self.entry
        own = entry.name_de if language == "de" and entry.name_de else entry.name
        if isinstance(entry, Parameter) and entry.subcode_name:
            return f"{own}: {entry.subcode_name}"
        if isinstance(entry, ObjectEntry) and entry.object_name and entry.object_type != "VAR":
            return f"{entry.object_name}: {own}"
        return own

    @property
    def label(self) -> str:
        """The code as a user reads it: ``C0012 · set 2`` for C2012, else the ref."""
        if self.parameter_set > 1 and isinstance(self.entry, Parameter):
            return f"{self.entry.ref} · set {self.parameter_set}"
        return self.ref

    @property
    def address(self) -> str:
        return f"0x{self.index:04X}sub{self.subindex}"

    @property
    def group(self) -> str:
        if self.entry.group:
            return self.entry.group
        return "Communication objects" if self.index < 0x2000 else "Device profile objects"


def index_ref(index: int, subindex: int) -> str:
    return f"0x{index:04X}" if subindex == 0 else f"0x{index:04X}.{subindex}"


class Catalog:
    """Lookup of a profile's items by vendor code, by index, or by search text."""

    def __init__(self, profile: Profile) -> None:
        self.profile = profile
        self._by_address: dict[tuple[int, int], Item] = {}
        self._by_code: dict[tuple[str, int], Item] = {}
        for par in profile.parameters:
            number = int("".join(ch for ch in par.code if ch.isdigit()))
            if par.index is not None:
                index, sub = par.index, par.subindex if par.subindex is not None else par.subcode
            else:
                index, sub = code_to_index(profile.addressing, number, par.subcode)
            item = Item(par.ref, index, sub, par)
            self._by_address.setdefault((index, sub), item)
            self._by_code[(par.code.upper(), par.subcode)] = item
        for obj in profile.objects:
            item = Item(index_ref(obj.index, obj.subindex), obj.index, obj.subindex, obj)
            self._by_address.setdefault((obj.index, obj.subindex), item)
        self._sub_zero = _sub_zero_items(self._by_address)

    @cached_property
    def items(self) -> list[Item]:
        """Every item: vendor parameters first (the manual's order), then CANopen objects by index."""
        params = [i for i in self._by_code.values()]
        objects = sorted((i for i in self._by_address.values() if not isinstance(i.entry, Parameter)),
                         key=lambda i: (i.index, i.subindex))
        return params + objects

    @cached_property
    def parameter_sets(self) -> int:
        """How many parameter sets the profile's codes have (Lenze 8200 vector: 4; most devices 1)."""
        return max((p.parameter_sets for p in self.profile.parameters), default=1)

    def in_set(self, item: Item, parameter_set: int) -> Item:
        """``item`` in ``parameter_set`` (C0012 -> C2012 for set 2) where its code exists per set, else ``item``."""
        entry = item.entry
        if parameter_set == 1 or not isinstance(entry, Parameter) or entry.parameter_sets < parameter_set:
            return item
        number, pset = code_parameter_set(self.profile.addressing, _number(entry.code))
        code = format_code(self.profile.addressing, "C", number + (parameter_set - pset) * _set_offset(self))
        return self.resolve(code if entry.subcode == 0 else f"{code}/{entry.subcode}")

    @cached_property
    def set_items(self) -> list[Item]:
        """The codes of parameter sets 2 and up (C2012 for C0012 ...), set by set in the profile's order."""
        return [self.in_set(item, number) for number in range(2, self.parameter_sets + 1) for item in self.items
                if isinstance(item.entry, Parameter) and item.entry.parameter_sets >= number]

    @cached_property
    def _set_addresses(self) -> dict[tuple[int, int], Item]:
        return {(item.index, item.subindex): item for item in self.set_items}

    def by_address(self, index: int, subindex: int) -> Item | None:
        """The item at this address; a code of parameter set 2 and up (0x5823: C2012) where the profile lists its
        set 1 code."""
        found = self._by_address.get((index, subindex))
        if found is None and subindex == 0:
            found = self._sub_zero.get(index)
        if found is None and self.parameter_sets > 1:
            return self._set_addresses.get((index, subindex))
        return found

    def unlisted_index(self, ref: IndexRef | CodeRef) -> Item | None:
        """An index of a parameter the profile lists only as ``.0`` (MICROMASTER ``P0700.1``): that parameter at
        sub-index n, where the addressing rule makes the index after the point the sub-index (the device aborts
        0x06090011 if it has none)."""
        if not self.profile.addressing.point_is_subindex or not isinstance(ref, CodeRef) or not ref.subcode:
            return None
        try:
            base = self.resolve(f"{ref.prefix}{ref.number}")
        except UnknownParameter:
            return None
        return Item(f"{base.ref}.{ref.subcode}", base.index, ref.subcode, base.entry)

    def resolve(self, text: str) -> Item:
        """Resolve what a user typed. Raises UnknownParameter naming the device."""
        ref = parse_ref(text)
        if isinstance(ref, IndexRef):
            sub = ref.subindex if ref.subindex is not None else 0
            item = self._by_address.get((ref.index, sub)) or (self._sub_zero.get(ref.index) if sub == 0 else None)
            if item is None:
                raise UnknownParameter(_("{object} is not in the profile '{product}'").format(
                    object=f"0x{ref.index:04X}sub{sub}", product=self.profile.identity.product_name))
            return item
        return self._resolve_code(ref, text)

    def _resolve_code(self, ref: CodeRef, text: str) -> Item:
        prefixes = ["C"] if ref.prefix in ("", "C") else [ref.prefix.upper(), "P", "R"]
        subcode = ref.subcode or 0
        addressing = self.profile.addressing
        for prefix in prefixes:
            for digits in (5, 4, 0):
                code = f"{prefix}{ref.number:0{digits}d}" if digits else f"{prefix}{ref.number}"
                item = self._by_code.get((code.upper(), subcode))
                if item is not None:
                    return item
        # Lenze parameter sets: C2011 is C0011 in parameter set 2.
        base_number, pset = code_parameter_set(addressing, ref.number)
        if pset > 1:
            base = self._resolve_code(CodeRef(ref.prefix, base_number, ref.subcode), text)
            if isinstance(base.entry, Parameter) and base.entry.parameter_sets >= pset:
                index, sub = code_to_index(addressing, ref.number, subcode)
                name = format_code(addressing, "C", ref.number)
                return Item(name if subcode == 0 else f"{name}/{subcode}", index, sub, base.entry, pset)
        raise UnknownParameter(_("'{text}' is not a parameter of '{product}'").format(
            text=text, product=self.profile.identity.product_name))

    def search(self, text: str) -> list[Item]:
        """Items whose code, index or name matches ``text`` (``88``, ``C00088``, ``rated motor current``,
        ``0x5FA7``, ``5FA7sub0``)."""
        query = text.strip().lower()
        if not query:
            return self.items
        exact: list[Item] = []
        with contextlib.suppress(UnknownParameter):
            exact = [self.resolve(text)]
        words = query.split()
        hits = [
            item for item in self.items
            if item not in exact and (
                all(w in item.name.lower() for w in words)
                or query in item.ref.lower()
                or query.replace("0x", "") in item.address.lower()
            )
        ]
        return exact + hits

    def vendor_ref(self, index: int, subindex: int) -> str:
        """The name to show for an address, even one the profile does not list."""
        item = self._by_address.get((index, subindex))
        if item is not None:
            return item.ref
        found = index_to_code(self.profile.addressing, index, subindex)
        if found is None:
            return index_ref(index, subindex)
        number, sub = found
        prefix = self.profile.addressing.prefix
        code = format_code(self.profile.addressing, prefix, number)
        return code if sub == 0 else f"{code}/{sub}"


def _sub_zero_items(by_address: dict[tuple[int, int], Item]) -> dict[int, Item]:
    """Sub 0 of every array/record whose profile lists only its members: "Highest sub-index supported",
    UNSIGNED8, read-only, the highest listed sub-index (CiA 301; the exported EDS declares it the same way)."""
    members: dict[int, list[Item]] = {}
    for (index, _sub), item in by_address.items():
        members.setdefault(index, []).append(item)
    found: dict[int, Item] = {}
    for index, items in members.items():
        if (index, 0) in by_address:
            continue
        first = min(items, key=lambda i: i.subindex)
        entry = first.entry
        if isinstance(entry, ObjectEntry):
            object_name, object_type = entry.object_name or entry.name, entry.object_type
        else:
            code = entry.code if isinstance(entry, Parameter) else ""
            object_name, object_type = f"{code}: {entry.name}" if code else entry.name, "RECORD"
        highest = max(i.subindex for i in items)
        found[index] = Item(index_ref(index, 0), index, 0, ObjectEntry(
            index=index, subindex=0, name="Highest sub-index supported", object_name=object_name,
            object_type="RECORD" if object_type == "VAR" else object_type, data_type=DataType.UNSIGNED8,
            access=Access.RO, default=highest))
    return found


def _number(code: str) -> int:
    return int("".join(ch for ch in code if ch.isdigit()))


def _set_offset(catalog: Catalog) -> int:
    addressing = catalog.profile.addressing
    return addressing.set_offset if isinstance(addressing, CodeAddressing) else 0
