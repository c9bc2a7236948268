"""PDO configuration of a node: read it, check a new mapping against the profile, apply it in the CiA 301 order.

Apply order (CiA 301 7.5.2.35-38): 1 COB-ID with the invalid bit set, 2 mapping count 0, 3 the entries,
4 the count, 5 transmission type, inhibit time and event timer, 6 COB-ID valid; then everything is read back.
A failed step stops the sequence; since step 1 made the PDO invalid, a failure never leaves it half-mapped and
enabled, and the report says which step failed with its abort code.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field, PrivateAttr

from drivebench.device.calculators.cobids import alternative_hint
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles import pdo_notes
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.loader import original_file
from drivebench.device.profiles.profile import Access, Entry, ObjectEntry
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import DriveBenchError, InvalidValue, NotFound, ProtocolError, SdoAbortError
from drivebench.i18n import N_, _
from drivebench.protocol.datatypes import DataType, decode
from drivebench.services.bus.sessions import Session
from drivebench.services.params import node_lease, writes
from drivebench.services.params.write_context import WriteContext

Direction = Literal["rpdo", "tpdo"]
COMM_BASE: dict[str, int] = {"rpdo": 0x1400, "tpdo": 0x1800}
MAP_BASE: dict[str, int] = {"rpdo": 0x1600, "tpdo": 0x1A00}
COB_INVALID = 1 << 31
COB_NO_RTR = 1 << 30
MAX_PDO_BITS = 64
AUDIT_ORIGIN = "pdo"


class MappedObject(BaseModel):
    index: int
    subindex: int
    bits: int
    name: str
    ref: str
    unit: str | None = None


class DeviceSetting(BaseModel):
    """A vendor code that shapes the PDO (Lenze monitoring time, MICROMASTER P2041 ...), as the device holds it."""

    ref: str
    name: str
    value: str
    """Scaled, with unit or selection text; a bit field in hex; or why it could not be read."""
    text: str | None = None
    """The set bits' names of a bit field, or the abort text."""


class PdoConfig(BaseModel):
    direction: Direction
    number: int
    cob_id: int
    valid: bool
    rtr_allowed: bool
    transmission_type: int
    transmission_text: str
    inhibit_time_ms: float | None = None
    event_timer_ms: int | None = None
    sync_start: int | None = None
    entries: list[MappedObject]
    length_bytes: int
    max_entries: int
    fixed_mapping: bool = False
    static_mapping: bool = False
    """The mapping count reads 0 and the device still carries fixed objects (8400 motec port words): those are
    ``entries``."""
    transmission_note: str | None = None
    """Where the manual says the type is not permitted (or special) for this device."""
    notes: list[str] = Field(default_factory=list)
    settings: list[DeviceSetting] = Field(default_factory=list)
    conflicts: list[str] = Field(default_factory=list)
    """The COB-ID is also a predefined identifier of another node of the session (e.g. Lenze base IDs)."""


class PdoWrite(BaseModel):
    cob_id: int | None = Field(None, ge=0x001, le=0x7FF, description="11-bit identifier; omitted = keep")
    valid: bool = True
    transmission_type: int | None = Field(None, ge=0, le=255)
    inhibit_time_ms: float | None = Field(None, ge=0, le=6553.5)
    event_timer_ms: int | None = Field(None, ge=0, le=65535)
    entries: list[tuple[int, int]] = Field(description="(index, subindex) of each mapped object, in order")


class ApplyStep(BaseModel):
    step: str
    index: int
    subindex: int
    value: str
    ok: bool
    abort_code: str | None = None
    abort_text: str | None = None
    detail: str | None = None
    _error: ProtocolError | None = PrivateAttr(None)

    @property
    def error(self) -> ProtocolError | None:
        """Why the step failed (an abort, no answer ...), for the status a report is answered with."""
        return self._error


class ApplyReport(BaseModel):
    ok: bool
    enabled: bool
    message: str
    steps: list[ApplyStep]
    pdo: PdoConfig | None = None


def transmission_text(trans_type: int, direction: Direction) -> str:
    """CiA 301's meaning of a transmission type, in the reader's language."""
    if trans_type == 0:
        return _("synchronous, acyclic (sent on SYNC after a change)") if direction == "tpdo" else \
            _("synchronous, acyclic")
    if 1 <= trans_type <= 240:
        return _("synchronous, every {count}. SYNC").format(count=trans_type) if trans_type > 1 else \
            _("synchronous, every SYNC")
    if trans_type in (252, 253):
        return _("RTR only, synchronous") if trans_type == 252 else _("RTR only, event-driven")
    if trans_type in (254, 255):
        return _("event-driven (manufacturer-specific)") if trans_type == 254 else _("event-driven (device profile)")
    return _("reserved")


# CiA 301 predefined connection set: base -> what a node n sends (producer) or receives on base + n
PREDEFINED: dict[int, tuple[str, bool]] = {
    0x080: ("EMCY", True), 0x180: ("TPDO1", True), 0x280: ("TPDO2", True), 0x380: ("TPDO3", True),
    0x480: ("TPDO4", True), 0x200: ("RPDO1", False), 0x300: ("RPDO2", False), 0x400: ("RPDO3", False),
    0x500: ("RPDO4", False), 0x580: ("SDO (tx)", True), 0x600: ("SDO (rx)", False), 0x700: (N_("heartbeat"), True)}


def cob_id_conflicts(session: Session, node_id: int, direction: Direction, cob_id: int) -> list[str]:
    """Where a PDO's COB-ID is also a predefined identifier of another node of the session, in words.

    The classic case is the Lenze base ID of RPDO2 (0x281 + n, 8400 motec C00353 = 0): it is TPDO2 of node n + 1;
    where the node's profile has such alternative base identifiers (``switches.cob_ids``), the message names them.
    """
    found = []
    own = session.nodes.get(node_id)
    hint = alternative_hint(own.profile.switches if own and own.profile else None, node_id, cob_id)
    for other in sorted(session.nodes):
        if other == node_id:
            continue
        for base, (name, produces) in PREDEFINED.items():
            if base + other != cob_id:
                continue
            cob, name = f"0x{cob_id:03X}", _(name)
            if direction == "rpdo" and produces:
                found.append((_("COB-ID {cob} is also {name} of node {other}: this RPDO receives what node {other} "
                                "sends - wanted only for cross communication ({hint}?).") if hint else
                              _("COB-ID {cob} is also {name} of node {other}: this RPDO receives what node {other} "
                                "sends - wanted only for cross communication.")).format(cob=cob, name=name,
                                                                                        other=other, hint=hint))
            elif direction == "tpdo":
                what = _("two producers on one identifier") if produces else \
                    _("node {other} would act on this TPDO").format(other=other)
                found.append(_("COB-ID {cob} is also {name} of node {other}: {what}.").format(
                    cob=cob, name=name, other=other, what=what))
    return found


def node_catalog(session: Session, node_id: int) -> Catalog:
    catalog = session.node(node_id).catalog
    if catalog is None:
        raise NotFound(_("Node {node} has no device profile: its PDOs cannot be named or checked.").format(
            node=node_id), hint=N_("Scan the bus or pick the node's profile on the Plant page."))
    return catalog


def profile_entry(catalog: Catalog, index: int, sub: int) -> ObjectEntry | Entry | None:
    item = catalog.by_address(index, sub)
    return item.entry if item else None


def pdo_numbers(session: Session, node_id: int, direction: Direction) -> list[int]:
    catalog = node_catalog(session, node_id)
    base = COMM_BASE[direction]
    return sorted({o.index - base + 1 for o in catalog.profile.objects
                   if base <= o.index < base + 0x200 and o.subindex == 1})


def mappable_objects(session: Session, node_id: int, direction: Direction) -> list[MappedObject]:
    """What the profile allows in a PDO of this direction (RPDO: writable objects, TPDO: readable ones)."""
    catalog = node_catalog(session, node_id)
    found: list[MappedObject] = []
    seen: set[tuple[int, int]] = set()
    for item in catalog.items:  # CANopen objects and vendor codes (Lenze AIF words C1822/1 = 0x58E1.1 ...)
        entry = item.entry
        if not entry.pdo_mappable or entry.data_type.size is None or (item.index, item.subindex) in seen:
            continue
        if item.parameter_set != 1 or (direction == "rpdo" and not entry.access.writable):
            continue
        # CiA 306: rww objects are process inputs (RPDO only), rwr process outputs (TPDO only)
        if (direction == "tpdo" and entry.access in (Access.RWW, Access.WO)) or (
                direction == "rpdo" and entry.access is Access.RWR):
            continue
        if catalog.by_address(item.index, item.subindex) is not item:
            continue  # an object listed twice (code and index): name it once, as the catalog does
        seen.add((item.index, item.subindex))
        found.append(_mapped(catalog, item.index, item.subindex, entry.data_type.size * 8))
    return sorted(found, key=lambda m: (m.index, m.subindex))


def _mapped(catalog: Catalog, index: int, sub: int, bits: int) -> MappedObject:
    item = catalog.by_address(index, sub)
    if 0x0001 <= index <= 0x0007 and sub == 0:
        return MappedObject(index=index, subindex=0, bits=bits, name=_("dummy entry"), ref=f"0x{index:04X}.0")
    return MappedObject(index=index, subindex=sub, bits=bits, name=item.name if item else _("not in the profile"),
                        ref=catalog.vendor_ref(index, sub), unit=item.entry.unit if item else None)


async def read_u32(session: Session, node_id: int, index: int, sub: int) -> int:
    raw = decode(DataType.UNSIGNED32, (await session.client(node_id).aupload(index, sub)).ljust(4, b"\0")[:4])
    assert isinstance(raw, int)
    return raw


async def _optional(session: Session, node_id: int, catalog: Catalog, index: int, sub: int) -> int | None:
    if catalog.by_address(index, sub) is None:
        return None
    return await read_u32(session, node_id, index, sub)


async def _settings(session: Session, node_id: int, catalog: Catalog, refs: list[str]) -> list[DeviceSetting]:
    found = []
    for ref in refs:
        try:
            item = catalog.resolve(ref)
        except DriveBenchError:
            continue  # not in this profile's parameter list
        entry, size = item.entry, item.entry.data_type.size or 4
        try:
            raw = decode(entry.data_type, (await session.client(node_id).aupload(item.index, item.subindex))
                         .ljust(size, b"\0")[:size])
            scaled = from_raw(entry, raw)
            shown, text = scaled.display(), None
            if entry.bits and isinstance(raw, int):  # a bit field (P2041.02): hex here, the bits' names on hover
                shown, text = f"0x{raw:0{2 * size}X}", scaled.text
            elif isinstance(raw, int) and size > 1 and not (entry.unit or entry.selection or entry.factor != 1):
                shown = f"{raw} (0x{raw:0{2 * size}X})"  # bytes with meanings (P2041.00: TPDO1/TPDO5 types)
        except SdoAbortError as exc:
            shown, text = _("not readable: 0x{code}").format(code=f"{exc.abort_code:08X}"), exc.abort_text
        found.append(DeviceSetting(ref=item.ref, name=item.name, value=shown, text=text))
    return found


async def read_mapping(session: Session, node_id: int, catalog: Catalog, mapping: int) -> list[MappedObject]:
    """The entries of mapping object ``mapping`` (0x1600, 0x1A00 ...) as the device holds them, named."""
    count = await read_u32(session, node_id, mapping, 0)
    entries = []
    for sub in range(1, count + 1):
        value = await read_u32(session, node_id, mapping, sub)
        entries.append(_mapped(catalog, value >> 16, (value >> 8) & 0xFF, value & 0xFF))
    return entries


def max_mapping_entries(catalog: Catalog, mapping: int) -> int:
    return max((o.subindex for o in catalog.profile.objects if o.index == mapping), default=0)


def mapping_plan(mapping: int, chosen: list[MappedObject]) -> list[tuple[str, int, int, int, int]]:
    """CiA 301 steps 2-4: count 0, the entries, the count - as (step, index, sub, value, size)."""
    plan = [(_("disable mapping (count 0)"), mapping, 0, 0, 1)]
    plan += [(_("entry {number}: {ref} {name}").format(number=n, ref=m.ref, name=m.name), mapping, n,
              (m.index << 16) | (m.subindex << 8) | m.bits, 4) for n, m in enumerate(chosen, start=1)]
    plan.append((_("enable mapping (count {count})").format(count=len(chosen)), mapping, 0, len(chosen), 1))
    return plan


async def run_plan(session: Session, node_id: int, plan: list[tuple[str, int, int, int, int]], ctx: WriteContext
                   ) -> list[ApplyStep]:
    """Download the plan's steps in order, each in the audit log as ``ctx``'s with the origin ``pdo``; stops at the
    first refused one (the last step, ``ok`` False)."""
    ctx = ctx.as_origin(AUDIT_ORIGIN)
    steps: list[ApplyStep] = []
    for name, index, sub, value, size in plan:
        step = ApplyStep(step=name, index=index, subindex=sub, value=f"0x{value:0{size * 2}X}", ok=True)
        steps.append(step)
        try:
            await writes.send_logged(session, node_id, index, sub, value.to_bytes(size, "little"), ctx=ctx)
        except SdoAbortError as exc:
            step.ok, step.abort_code, step.abort_text, step._error = (False, f"0x{exc.abort_code:08X}",
                                                                      exc.abort_text, exc)
            break
        except ProtocolError as exc:
            step.ok, step.detail, step._error = False, exc.detail, exc
            break
    return steps


async def read_pdo(session: Session, node_id: int, direction: Direction, number: int) -> PdoConfig:
    catalog = node_catalog(session, node_id)
    comm, mapping = COMM_BASE[direction] + number - 1, MAP_BASE[direction] + number - 1
    if catalog.by_address(comm, 1) is None:
        raise NotFound(_("{device} has no {pdo} (object 0x{index} is not in its profile).").format(
            device=session.node(node_id).device_name, pdo=f"{direction.upper()}{number}", index=f"{comm:04X}"))
    cob = await read_u32(session, node_id, comm, 1)
    trans_type = await _optional(session, node_id, catalog, comm, 2)
    inhibit = await _optional(session, node_id, catalog, comm, 3) if direction == "tpdo" else None
    event = await _optional(session, node_id, catalog, comm, 5)
    sync_start = await _optional(session, node_id, catalog, comm, 6)
    entries = await read_mapping(session, node_id, catalog, mapping)
    static = [] if entries else _static_entries(catalog, direction, number)
    max_entries = max_mapping_entries(catalog, mapping)
    trans = 255 if trans_type is None else trans_type
    entry_one = profile_entry(catalog, mapping, 1)
    profile = catalog.profile
    notes = pdo_notes.pdo_notes(profile, direction, number)
    static_note = pdo_notes.static_mapping_note(profile, direction, number)
    if static:
        entries = static
        if static_note:
            notes.insert(0, static_note)
    selecting = pdo_notes.mapping_bits_note(profile, direction, number, [(e.index, e.subindex) for e in entries])
    if selecting and entries:
        notes.append(selecting[0].upper() + selecting[1:] + ".")
    settings = await _settings(session, node_id, catalog, pdo_notes.setting_refs(profile, direction, number))
    conflicts = cob_id_conflicts(session, node_id, direction, cob & 0x7FF)
    return PdoConfig(settings=settings, conflicts=conflicts, static_mapping=bool(static),
                     fixed_mapping=entry_one is None or not entry_one.access.writable,
                     transmission_note=pdo_notes.transmission_note(profile, direction, trans),
                     notes=notes,
                     direction=direction, number=number, cob_id=cob & 0x7FF, valid=not cob & COB_INVALID,
                     rtr_allowed=not cob & COB_NO_RTR, transmission_type=trans,
                     transmission_text=transmission_text(trans, direction),
                     inhibit_time_ms=inhibit / 10 if inhibit is not None else None, event_timer_ms=event,
                     sync_start=sync_start, entries=entries, length_bytes=sum(e.bits for e in entries) // 8,
                     max_entries=max_entries)


def _static_entries(catalog: Catalog, direction: Direction, number: int) -> list[MappedObject]:
    found = []
    for ref in pdo_notes.static_mapping(catalog.profile, direction, number):
        try:
            item = catalog.resolve(ref)
        except DriveBenchError:
            return []  # a profile without the port words: count 0 shows as nothing mapped
        found.append(_mapped(catalog, item.index, item.subindex, (item.entry.data_type.size or 0) * 8))
    return found


async def read_pdos(session: Session, node_id: int) -> list[PdoConfig]:
    return [await read_pdo(session, node_id, direction, number)
            for direction in ("rpdo", "tpdo") for number in pdo_numbers(session, node_id, direction)]


def check_mapping(session: Session, node_id: int, direction: Direction, number: int, entries: list[tuple[int, int]],
                  *, name: str, max_bits: int | None = MAX_PDO_BITS) -> list[MappedObject]:
    """The new mapping, named; InvalidValue before anything is sent when the profile forbids it. ``name``: the
    PDO as its bus names it (``RPDO1``, ``RxPDO 0x1600``); ``max_bits``: a CAN frame's 8 bytes, None where the
    number of entries bounds it (EtherCAT)."""
    catalog = node_catalog(session, node_id)
    mapping_index = MAP_BASE[direction] + number - 1
    entry_one = profile_entry(catalog, mapping_index, 1)
    if entry_one is None or not entry_one.access.writable:
        raise InvalidValue(_("The mapping of {pdo} is fixed on this device (its entries are read-only in the "
                             "profile).").format(pdo=name))
    max_entries = max_mapping_entries(catalog, mapping_index)
    if len(entries) > max_entries:
        raise InvalidValue(_("{pdo} takes at most {count} mapping entries; {given} were given.").format(
            pdo=name, count=max_entries, given=len(entries)))
    allowed = {(o.index, o.subindex): o for o in mappable_objects(session, node_id, direction)}
    for index, sub in entries:
        if (index, sub) not in allowed:
            item = catalog.by_address(index, sub)
            what = f"{catalog.vendor_ref(index, sub)} ({item.name})" if item else f"0x{index:04X}.{sub}"
            text = (_("{what} cannot be mapped into {pdo}: the profile does not list it as PDO-mappable and "
                      "writable (what this PDO carries is written into the device).") if direction == "rpdo" else
                    _("{what} cannot be mapped into {pdo}: the profile does not list it as PDO-mappable (what "
                      "this PDO carries is read from the device)."))
            raise InvalidValue(text.format(what=what, pdo=name))
    chosen = [allowed[entry] for entry in entries]
    bits = sum(m.bits for m in chosen)
    if max_bits is not None and bits > max_bits:
        raise InvalidValue(_("The mapping needs {count} bytes; a PDO carries at most 8.").format(count=bits // 8))
    rule = pdo_notes.mapping_rule_violation(catalog.profile, direction, number, entries)
    if rule:
        raise InvalidValue(rule)
    return chosen


def _check_transmission_type(catalog: Catalog, direction: Direction, number: int,
                             transmission_type: int | None) -> None:
    """InvalidValue before anything is sent when the device's manual does not permit the type."""
    if transmission_type is None:
        return
    entry = profile_entry(catalog, COMM_BASE[direction] + number - 1, 2)
    if entry is not None and entry.selection and transmission_type not in entry.selection:
        allowed_types = ", ".join(f"{k} ({v})" for k, v in sorted(entry.selection.items()))
        raise InvalidValue(_("Transmission type {type} is not permitted for this device; its manual allows "
                             "{allowed}.").format(type=transmission_type, allowed=allowed_types))
    if entry is not None and entry.max is not None and transmission_type > entry.max:
        raise InvalidValue(_("Transmission type {type} is above the device's maximum {max}.").format(
            type=transmission_type, max=f"{entry.max:g}"))


async def apply_pdo(session: Session, node_id: int, direction: Direction, number: int,
                    write: PdoWrite, *, ctx: WriteContext) -> ApplyReport:
    """Refused (409) while another writer holds the node's lease (``ctx``'s writer takes it); holds it until the
    last step."""
    node_catalog(session, node_id)
    with node_lease.writing(session, node_id, ctx):
        return await _apply_pdo(session, node_id, direction, number, write, ctx)


async def _apply_pdo(session: Session, node_id: int, direction: Direction, number: int,
                     write: PdoWrite, ctx: WriteContext) -> ApplyReport:
    catalog = node_catalog(session, node_id)
    chosen = check_mapping(session, node_id, direction, number, write.entries, name=f"{direction.upper()}{number}")
    _check_transmission_type(catalog, direction, number, write.transmission_type)
    comm, mapping = COMM_BASE[direction] + number - 1, MAP_BASE[direction] + number - 1
    current = await read_pdo(session, node_id, direction, number)
    cob_id = write.cob_id if write.cob_id is not None else current.cob_id
    flags = 0 if current.rtr_allowed else COB_NO_RTR
    plan: list[tuple[str, int, int, int, int]] = [
        (_("disable PDO (COB-ID invalid)"), comm, 1, cob_id | flags | COB_INVALID, 4), *mapping_plan(mapping, chosen)]
    if write.transmission_type is not None:
        plan.append((_("transmission type"), comm, 2, write.transmission_type, 1))
    if write.inhibit_time_ms is not None and direction == "tpdo" and catalog.by_address(comm, 3):
        plan.append((_("inhibit time"), comm, 3, round(write.inhibit_time_ms * 10), 2))
    if write.event_timer_ms is not None and catalog.by_address(comm, 5):
        plan.append((_("event timer"), comm, 5, write.event_timer_ms, 2))
    if write.valid:
        plan.append((_("enable PDO (COB-ID valid)"), comm, 1, cob_id | flags, 4))

    steps = await run_plan(session, node_id, plan, ctx)
    if not steps[-1].ok:
        return await _failed(session, node_id, direction, number, steps, disabled=len(steps) > 1)
    pdo = await read_pdo(session, node_id, direction, number)
    read_back = [] if pdo.static_mapping else pdo.entries  # count 0 written: the static mapping applies again
    mismatch = [m.ref for m, got in zip(chosen, read_back, strict=False) if (m.index, m.subindex) !=
                (got.index, got.subindex)] or ([] if len(read_back) == len(chosen) else [N_("entry count")])
    if mismatch or pdo.valid != write.valid or pdo.cob_id != cob_id:
        return ApplyReport(ok=False, enabled=pdo.valid, steps=steps, pdo=pdo,
                           message=_("{pdo} reads back differently from what was written ({what}).").format(
                               pdo=f"{direction.upper()}{number}",
                               what=", ".join(_(ref) if ref == "entry count" else ref for ref in mismatch)
                               or _("COB-ID/valid bit")))
    verified = _("{pdo} applied and verified: {static}{count} entries, {size} bytes, COB-ID 0x{cob}{disabled}.")
    return ApplyReport(ok=True, enabled=pdo.valid, steps=steps, pdo=pdo, message=verified.format(
        pdo=f"{direction.upper()}{number}", static=_("count 0 = static mapping, ") if pdo.static_mapping else "",
        count=len(chosen), size=pdo.length_bytes, cob=f"{pdo.cob_id:03X}",
        disabled="" if pdo.valid else _(", left disabled as requested")))


async def _failed(session: Session, node_id: int, direction: Direction, number: int, steps: list[ApplyStep],
                  *, disabled: bool) -> ApplyReport:
    try:
        pdo: PdoConfig | None = await read_pdo(session, node_id, direction, number)
    except ProtocolError:
        pdo = None
    failed = steps[-1]
    reason = f"{failed.abort_code} {failed.abort_text}" if failed.abort_code else (failed.detail or "")
    if not disabled:
        state = _("nothing was changed; the PDO keeps its previous configuration")
    elif pdo is None:
        state = _("the PDO could not be read back; step 1 had set its COB-ID invalid, so it should be disabled - "
                  "read the PDOs again to check")
    elif pdo.valid:
        state = _("the PDO reads back as ENABLED - check the device")
    else:
        state = _("the PDO is left disabled (COB-ID invalid), never half-mapped and enabled")
    return ApplyReport(ok=False, enabled=bool(pdo and pdo.valid), steps=steps, pdo=pdo,
                       message=_("{pdo}: step '{step}' failed ({reason}); {state}.").format(
                           pdo=f"{direction.upper()}{number}", step=failed.step, reason=reason, state=state))


async def export_dcf(session: Session, node_id: int) -> str:
    """A DCF of the node whose PDO communication and mapping objects hold the values read from the device."""
    catalog = node_catalog(session, node_id)
    values: dict[tuple[int, int], int] = {}
    for obj in catalog.profile.objects:
        if 0x1400 <= obj.index <= 0x1BFF and obj.access.readable and obj.data_type.size:
            try:
                raw = await session.client(node_id).aupload(obj.index, obj.subindex)
            except SdoAbortError:
                continue  # e.g. a reserved sub-index the device lists but refuses
            value = decode(obj.data_type, raw.ljust(obj.data_type.size, b"\0")[:obj.data_type.size])
            if isinstance(value, int):
                values[(obj.index, obj.subindex)] = value
    return export_eds(catalog.profile, node_id=node_id, values=values, dcf=True,
                      original=original_file(session.profiles, catalog.profile))
