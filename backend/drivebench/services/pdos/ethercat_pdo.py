"""PDO assignment and mapping of an EtherCAT slave over CoE: what Sync Manager 2/3 carry (0x1C12 RxPDO, 0x1C13
TxPDO) and the entries of each assigned mapping object (RxPDO 0x1600..., TxPDO 0x1A00...), decoded as for CANopen.

No COB-IDs, transmission types or SYNC: the master exchanges the process data cyclically. A mapping is written in
the CiA 301 order (sub 0 := 0, the entries, sub 0 := n); ETG.1000.6 and the 8400 motec EtherCAT manual allow it only
in Pre-Operational, elsewhere the slave aborts (0x08000022) and the report gives its words and the profile's rule.

A mapping the slave does not take raises :class:`MappingNotApplied` carrying the step report; its class says what
went wrong, and so the HTTP status (``web/problems.py``): refused in this EtherCAT state 409, a mapping the slave
finds invalid 422, no answer 504, anything else (another abort, a read-back that differs) 502.
"""

from __future__ import annotations

from pydantic import BaseModel, Field

from drivebench import errors
from drivebench.device.profiles import pdo_notes
from drivebench.device.profiles.catalog import Catalog
from drivebench.i18n import N_, _, ngettext
from drivebench.services.bus.sessions import Session
from drivebench.services.params import node_lease
from drivebench.services.params.write_context import WriteContext
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import ApplyStep, Direction, MappedObject

ASSIGNMENT: dict[Direction, int] = {"rpdo": 0x1C12, "tpdo": 0x1C13}
SYNC_MANAGER: dict[str, int] = {"rpdo": 2, "tpdo": 3}
KIND: dict[str, str] = {"rpdo": "RxPDO", "tpdo": "TxPDO"}
STATE_ABORTS = frozenset({0x08000021, 0x08000022})
"""Local control, device state: the slave takes the mapping in another state (ETG.1000.6: Pre-Operational)."""
INVALID_ABORTS = frozenset({0x06010002, 0x06040041, 0x06040042, 0x06040043, 0x06070010, 0x06070012, 0x06070013,
                            0x06090011, 0x06090030, 0x06090031, 0x06090032})
"""The slave finds the mapping itself wrong: read-only, not mappable, too long, no such entry, out of range."""


class EcatPdo(BaseModel):
    direction: Direction
    number: int
    """1 for 0x1600/0x1A00, 2 for 0x1601/0x1A01 ..."""
    mapping_index: int
    entries: list[MappedObject]
    length_bytes: int
    max_entries: int
    fixed_mapping: bool
    notes: list[str] = Field(default_factory=list)
    """The profile's words on this PDO (``pdo_rules.pdos``): what the manual says about its mapping."""


class EcatAssignment(BaseModel):
    direction: Direction
    index: int
    """0x1C12 or 0x1C13."""
    sync_manager: int
    writable: bool
    pdos: list[EcatPdo]


class EcatApplyReport(BaseModel):
    ok: bool
    message: str
    steps: list[ApplyStep]
    rule: str | None = None
    """The profile's words on the refusal (the manual's note naming the abort code)."""
    pdo: EcatPdo | None = None


class MappingNotApplied(errors.ProtocolError):
    """The slave answered, but the mapping is not what was written (another abort, a read-back that differs)."""

    title = N_("PDO mapping not applied")

    def __init__(self, report: EcatApplyReport) -> None:
        super().__init__(report.message)
        self.report = report

    def extra(self) -> dict[str, object]:
        return {**super().extra(), **self.report.model_dump(mode="json")}


class MappingRefusedInState(MappingNotApplied, errors.Conflict):
    title = N_("PDO mapping refused in this EtherCAT state")


class InvalidMapping(MappingNotApplied, errors.InvalidValue):
    title = N_("PDO mapping refused by the slave")


class MappingUnanswered(MappingNotApplied, errors.NodeOffline):
    title = N_("No answer to the PDO mapping")


def pdo_name(direction: Direction, number: int) -> str:
    """``RxPDO 0x1600``, ``TxPDO 0x1A01``: EtherCAT names a PDO by its mapping object."""
    return f"{KIND[direction]} 0x{pdo.MAP_BASE[direction] + number - 1:04X}"


def _catalog(session: Session, node_id: int) -> Catalog:
    if session.network.capabilities.frames:
        raise errors.Conflict(_("Session {session} is not an EtherCAT session: its PDOs have COB-IDs (PDO tab).")
                              .format(session=session.id))
    return pdo.node_catalog(session, node_id)


def _writable(catalog: Catalog, index: int, sub: int) -> bool:
    entry = pdo.profile_entry(catalog, index, sub)
    return entry is not None and entry.access.writable


def _mapping_object(session: Session, node_id: int, direction: Direction, number: int) -> tuple[Catalog, int]:
    """The node's catalog and the index of the mapping object (NotFound where the profile has none)."""
    catalog = _catalog(session, node_id)
    mapping = pdo.MAP_BASE[direction] + number - 1
    if catalog.by_address(mapping, 0) is None:
        raise errors.NotFound(_("{device} has no {pdo} in its profile.").format(
            device=session.node(node_id).device_name, pdo=pdo_name(direction, number)))
    return catalog, mapping


async def read_mapping_object(session: Session, node_id: int, direction: Direction, number: int) -> EcatPdo:
    catalog, mapping = _mapping_object(session, node_id, direction, number)
    entries = await pdo.read_mapping(session, node_id, catalog, mapping)
    return EcatPdo(direction=direction, number=number, mapping_index=mapping, entries=entries,
                   length_bytes=sum(e.bits for e in entries) // 8,
                   max_entries=pdo.max_mapping_entries(catalog, mapping),
                   fixed_mapping=not _writable(catalog, mapping, 1),
                   notes=pdo_notes.pdo_notes(catalog.profile, direction, number))


async def read_assignments(session: Session, node_id: int) -> list[EcatAssignment]:
    """0x1C12 and 0x1C13 as the slave holds them, each assigned PDO's mapping read and named."""
    catalog = _catalog(session, node_id)
    found = []
    for direction, index in ASSIGNMENT.items():
        if catalog.by_address(index, 0) is None:
            continue
        count = await pdo.read_u32(session, node_id, index, 0)
        pdos = []
        for sub in range(1, count + 1):
            mapping = (await pdo.read_u32(session, node_id, index, sub)) & 0xFFFF
            pdos.append(await read_mapping_object(session, node_id, direction,
                                                  mapping - pdo.MAP_BASE[direction] + 1))
        found.append(EcatAssignment(direction=direction, index=index, sync_manager=SYNC_MANAGER[direction],
                                    writable=_writable(catalog, index, 1), pdos=pdos))
    return found


def _rule(session: Session, node_id: int, abort_code: str | None) -> str | None:
    profile = session.node(node_id).profile
    if profile is None or abort_code is None:
        return None
    return next((note for note in pdo_notes.device_notes(profile) if abort_code in note), None)


async def _read_back(session: Session, node_id: int, direction: Direction,
                     number: int) -> tuple[EcatPdo | None, errors.ProtocolError | None]:
    try:
        return await read_mapping_object(session, node_id, direction, number), None
    except errors.ProtocolError as exc:
        return None, exc


def _failure(error: errors.ProtocolError | None) -> type[MappingNotApplied]:
    if isinstance(error, errors.SdoAbortError):
        if error.abort_code in STATE_ABORTS:
            return MappingRefusedInState
        if error.abort_code in INVALID_ABORTS:
            return InvalidMapping
    if isinstance(error, errors.SdoTimeoutError | errors.NodeOffline):
        return MappingUnanswered
    return MappingNotApplied


async def apply_mapping(session: Session, node_id: int, direction: Direction, number: int,
                        entries: list[tuple[int, int]], *, ctx: WriteContext) -> EcatApplyReport:
    """Write a mapping (refused 409 while another writer holds the node's lease), then read it back; raises
    :class:`MappingNotApplied` (its subclass says why) with the report when the slave does not take it."""
    _mapping_object(session, node_id, direction, number)  # 409 on a CANopen session, 404 where the profile has none
    name = pdo_name(direction, number)
    chosen = pdo.check_mapping(session, node_id, direction, number, entries, name=name, max_bits=None)
    with node_lease.writing(session, node_id, ctx):
        steps = await pdo.run_plan(session, node_id, pdo.mapping_plan(pdo.MAP_BASE[direction] + number - 1, chosen),
                                   ctx)
        read_back, unread = await _read_back(session, node_id, direction, number)
    failed = steps[-1]
    if not failed.ok:
        reason = f"{failed.abort_code} {failed.abort_text}" if failed.abort_code else (failed.detail or "")
        if len(steps) == 1:
            state = _("nothing was changed")
        elif read_back is None:
            state = _("it could not be read back: read the PDOs again")
        else:
            state = ngettext("it reads back with {n} entry", "it reads back with {n} entries",
                             len(read_back.entries)).format(n=len(read_back.entries))
        raise _failure(failed.error)(EcatApplyReport(
            ok=False, steps=steps, pdo=read_back, rule=_rule(session, node_id, failed.abort_code),
            message=_("{pdo}: step '{step}' refused ({reason}); {state}.").format(
                pdo=name, step=failed.step, reason=reason, state=state)))
    if read_back is None:
        raise _failure(unread)(EcatApplyReport(ok=False, steps=steps, message=_(
            "{pdo} was written, but reading it back failed ({reason}).").format(
                pdo=name, reason=unread.detail if unread else "")))
    if [(e.index, e.subindex) for e in read_back.entries] != [(m.index, m.subindex) for m in chosen]:
        raise MappingNotApplied(EcatApplyReport(ok=False, steps=steps, pdo=read_back, message=_(
            "{pdo} reads back differently from what was written.").format(pdo=name)))
    return EcatApplyReport(ok=True, steps=steps, pdo=read_back, message=ngettext(
        "{pdo} applied and verified: {n} entry, {size} bytes.", "{pdo} applied and verified: {n} entries, "
        "{size} bytes.", len(chosen)).format(pdo=name, n=len(chosen), size=read_back.length_bytes))
