"""PDO assignment and mapping of an EtherCAT slave over CoE: what Sync Manager 2/3 carry (0x1C12 RxPDO, 0x1C13
TxPDO) and the entries of each assigned mapping object (0x1600..., 0x1A00...), decoded as for CANopen.

No COB-IDs, transmission types or SYNC: the master exchanges the process data cyclically. A mapping is written in
the CiA 301 order (sub 0 := 0, the entries, sub 0 := n); ETG.1000.6 and the 8400 motec EtherCAT manual allow it only
in Pre-Operational, elsewhere the slave aborts (0x08000022) and the report gives its words and the profile's rule.
"""

from __future__ import annotations

from pydantic import BaseModel

from drivebench.device import pdo_notes
from drivebench.device.catalog import Catalog
from drivebench.errors import InvalidValue, NotFound
from drivebench.services.bus.sessions import Session
from drivebench.services.params import node_lease
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import ApplyStep, Direction, MappedObject, PdoWrite

ASSIGNMENT: dict[Direction, int] = {"rpdo": 0x1C12, "tpdo": 0x1C13}
SYNC_MANAGER: dict[str, int] = {"rpdo": 2, "tpdo": 3}


class EcatPdo(BaseModel):
    direction: Direction
    number: int
    """1 for 0x1600/0x1A00, 2 for 0x1601/0x1A01 ..."""
    mapping_index: int
    entries: list[MappedObject]
    length_bytes: int
    max_entries: int
    fixed_mapping: bool


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


def _catalog(session: Session, node_id: int) -> Catalog:
    if session.ethercat is None:
        raise InvalidValue(f"Session {session.id} is not an EtherCAT session: its PDOs have COB-IDs (PDO tab).")
    return pdo.node_catalog(session, node_id)


def _writable(catalog: Catalog, index: int, sub: int) -> bool:
    entry = pdo.profile_entry(catalog, index, sub)
    return entry is not None and entry.access.writable


async def read_mapping_object(session: Session, node_id: int, direction: Direction, number: int) -> EcatPdo:
    catalog = _catalog(session, node_id)
    mapping = pdo.MAP_BASE[direction] + number - 1
    if catalog.by_address(mapping, 0) is None:
        raise NotFound(f"{session.node(node_id).device_name} has no mapping object 0x{mapping:04X} in its profile.")
    entries = await pdo.read_mapping(session, node_id, catalog, mapping)
    return EcatPdo(direction=direction, number=number, mapping_index=mapping, entries=entries,
                   length_bytes=sum(e.bits for e in entries) // 8,
                   max_entries=pdo.max_mapping_entries(catalog, mapping),
                   fixed_mapping=not _writable(catalog, mapping, 1))


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


async def apply_mapping(session: Session, node_id: int, direction: Direction, number: int,
                        entries: list[tuple[int, int]]) -> EcatApplyReport:
    """Write a mapping (refused 409 while another writer holds the node's lease), then read it back."""
    _catalog(session, node_id)
    chosen = pdo.check_mapping(session, node_id, direction, number, PdoWrite(entries=entries), max_bits=None)
    mapping = pdo.MAP_BASE[direction] + number - 1
    name = f"0x{mapping:04X}"
    with node_lease.writing(session, node_id):
        steps = await pdo.run_plan(session, node_id, pdo.mapping_plan(mapping, chosen))
        read_back = await read_mapping_object(session, node_id, direction, number)
    failed = steps[-1]
    if not failed.ok:
        reason = f"{failed.abort_code} {failed.abort_text}" if failed.abort_code else (failed.detail or "")
        state = ("nothing was changed" if len(steps) == 1 else
                 f"it reads back with {len(read_back.entries)} entries")
        return EcatApplyReport(ok=False, steps=steps, pdo=read_back, rule=_rule(session, node_id, failed.abort_code),
                               message=f"{name}: step '{failed.step}' refused ({reason}); {state}.")
    if [(e.index, e.subindex) for e in read_back.entries] != [(m.index, m.subindex) for m in chosen]:
        return EcatApplyReport(ok=False, steps=steps, pdo=read_back,
                               message=f"{name} reads back differently from what was written.")
    return EcatApplyReport(ok=True, steps=steps, pdo=read_back,
                           message=f"{name} applied and verified: {len(chosen)} entries, "
                                   f"{read_back.length_bytes} bytes.")
