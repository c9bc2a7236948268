"""What a PDO recording changes on the nodes, written to the database BEFORE it changes anything, and the restore
from it: each TPDO back by the CiA 301 sequence, read back and compared; SYNC settings (0x1005/0x1006) compared
(and written back where they differ); the nodes the recording started back to pre-operational.

A TPDO whose mapping no longer holds what the recording wrote was remapped by someone else meanwhile: it is left
as it is and the restore says so (a third party's mapping is never overwritten silently). The record is removed
only after every read-back matched; a record left over (the server was killed mid-recording) is restored on the
next server start (:func:`restore_leftovers`).
"""

from __future__ import annotations

import asyncio
import logging
import os
import socket

from pydantic import BaseModel, Field
from sqlalchemy import select

from drivebench.errors import DriveBenchError, ProtocolError
from drivebench.i18n import N_, Text
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.params.write_context import LOCAL_USER, WriteContext
from drivebench.services.pdos import pdo
from drivebench.services.scope.pdo_plan import ScopePlan
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage import database
from drivebench.services.storage.models import ScopeRestoreRow

SERVER = f"{socket.gethostname()}:{os.getpid()}"
SYNC_OBJECTS = (0x1005, 0x1006)
"""COB-ID SYNC (bit 30: the node produces SYNC) and the communication cycle period."""
AUDIT_ORIGIN = "scope"
Written = dict[tuple[int, int], bool]
"""(node, TPDO number) -> whether a start finished configuring it (False: it began and failed halfway)."""
log = logging.getLogger(__name__)


class TpdoBefore(BaseModel):
    number: int
    comm: dict[int, int]
    """Sub-index -> value of the communication object (0x1800 + n - 1) before."""
    mapping: dict[int, int]
    """Sub-index -> value of the mapping object (0x1A00 + n - 1) before: sub 0 the count, then every entry."""
    wrote: list[int] = Field(default_factory=list)
    """The mapping entries the recording writes (a different mapping at the restore: someone else remapped it)."""


class NodeBefore(BaseModel):
    node: int
    profile_id: str | None
    tpdos: list[TpdoBefore]
    sync: dict[int, int] = Field(default_factory=dict)
    started: bool = False
    """The recording starts the node (NMT): the restore puts it back to pre-operational."""


class RestoreRecord(BaseModel):
    bus: str
    session: str
    nodes: list[NodeBefore]


async def _read(session: Session, node: int, index: int, sub: int) -> int:
    return await pdo.read_u32(session, node, index, sub)


async def _subs(session: Session, node: int, index: int, subs: list[int]) -> dict[int, int]:
    catalog = pdo.node_catalog(session, node)
    return {sub: await _read(session, node, index, sub) for sub in subs if catalog.by_address(index, sub)}


async def capture(session: Session, plan: ScopePlan) -> RestoreRecord:
    """Every value the recording will change on its nodes, as the nodes hold them now."""
    nodes = []
    for node in plan.pdo_nodes:
        catalog = pdo.node_catalog(session, node)
        tpdos = []
        for tpdo in (t for t in plan.tpdos if t.node == node):
            comm = pdo.COMM_BASE["tpdo"] + tpdo.number - 1
            mapping = pdo.MAP_BASE["tpdo"] + tpdo.number - 1
            entries = list(range(0, pdo.max_mapping_entries(catalog, mapping) + 1))
            tpdos.append(TpdoBefore(number=tpdo.number, comm=await _subs(session, node, comm, [1, 2, 3, 5]),
                                    mapping=await _subs(session, node, mapping, entries),
                                    wrote=[(m.index << 16) | (m.subindex << 8) | m.bits for m in tpdo.entries]))
        sync = {index: value for index in SYNC_OBJECTS for value in (await _subs(session, node, index, [0])).values()}
        profile = session.node(node).profile
        nodes.append(NodeBefore(node=node, profile_id=profile.id if profile else None, tpdos=tpdos, sync=sync,
                                started=node in plan.start_nodes))
    return RestoreRecord(bus=str(session.spec), session=session.id, nodes=nodes)


# --- the database -----------------------------------------------------------------------------------------------
def save(record: RestoreRecord, url: str | None = None) -> int:
    with database.transaction(url) as db:
        row = ScopeRestoreRow(bus=record.bus, server=SERVER, body=record.model_dump(mode="json"))
        db.add(row)
        db.flush()
        return row.id


def remove(record_id: int, url: str | None = None) -> None:
    with database.transaction(url) as db:
        row = db.get(ScopeRestoreRow, record_id)
        if row is not None:
            db.delete(row)


def leftovers(url: str | None = None) -> list[tuple[int, RestoreRecord]]:
    with database.transaction(url) as db:
        rows = db.scalars(select(ScopeRestoreRow).order_by(ScopeRestoreRow.id)).all()
        return [(row.id, RestoreRecord.model_validate(row.body)) for row in rows]


# --- the restore ------------------------------------------------------------------------------------------------
def _steps(number: int, before: TpdoBefore) -> list[tuple[str, int, int, int, int]]:
    comm = pdo.COMM_BASE["tpdo"] + number - 1
    mapping = pdo.MAP_BASE["tpdo"] + number - 1
    cob = before.comm.get(1, 0)
    count = before.mapping.get(0, 0)
    steps: list[tuple[str, int, int, int, int]] = [
        (Text(N_("disable PDO (COB-ID invalid)")), comm, 1, cob | pdo.COB_INVALID, 4),
        (Text(N_("disable mapping (count 0)")), mapping, 0, 0, 1)]
    steps += [(Text(N_("entry {number}"), number=sub), mapping, sub, value, 4)
              for sub, value in sorted(before.mapping.items()) if sub]
    steps.append((Text(N_("enable mapping (count {count})"), count=count), mapping, 0, count, 1))
    for sub, size, name in ((2, 1, N_("transmission type")), (3, 2, N_("inhibit time")), (5, 2, N_("event timer"))):
        if sub in before.comm:
            steps.append((Text(name), comm, sub, before.comm[sub], size))
    steps.append((Text(N_("COB-ID as before")), comm, 1, cob, 4))
    return steps


def failed_step(plan: list[tuple[str, int, int, int, int]], done: list[pdo.ApplyStep]) -> tuple[str, str]:
    """The name of the step of ``plan`` that failed (``done[-1]``) and why, both as made (a
    :class:`~drivebench.i18n.Text` is shown later in each reader's language): the device's abort text, the error's
    detail, else the abort code."""
    failed = done[-1]
    error = failed.error
    why: str = getattr(error, "abort_text", None) or (error.detail if error is not None else "") or \
        failed.abort_text or failed.detail or failed.abort_code or ""
    return plan[len(done) - 1][0], why


async def _restore_tpdo(session: Session, node: int, before: TpdoBefore, ctx: WriteContext,
                        check_remap: bool = True) -> tuple[bool, str]:
    """``check_remap``: a mapping that no longer holds what the recording wrote is someone else's and stays (False:
    a start that failed halfway, whose own half-written mapping it is)."""
    name = f"TPDO{before.number}"
    mapping = pdo.MAP_BASE["tpdo"] + before.number - 1
    now = [await _read(session, node, mapping, sub) for sub in range(1, len(before.wrote) + 1)] if check_remap else []
    count = await _read(session, node, mapping, 0) if check_remap else 0
    if check_remap and before.wrote and (count != len(before.wrote) or now != before.wrote):
        return False, Text(N_("Node {node}: {pdo} was remapped by someone else during the recording; it is left as "
                              "it is (not restored). Check it on the PDO tab."), node=node, pdo=name)
    plan = _steps(before.number, before)
    steps = await pdo.run_plan(session, node, plan, ctx.as_origin(AUDIT_ORIGIN))
    if not steps[-1].ok:
        step, why = failed_step(plan, steps)
        return False, Text(N_("Node {node}: restoring {pdo} failed at '{step}' ({why})."), node=node, pdo=name,
                           step=step, why=why)
    comm = pdo.COMM_BASE["tpdo"] + before.number - 1
    differ = [f"0x{comm:04X}.{sub}" for sub, value in before.comm.items()
              if await _read(session, node, comm, sub) != value]
    count_before = before.mapping.get(0, 0)
    differ += [f"0x{mapping:04X}.{sub}" for sub, value in before.mapping.items()
               if (sub == 0 or sub <= count_before) and await _read(session, node, mapping, sub) != value]
    if differ:
        return False, Text(N_("Node {node}: {pdo} reads back differently after the restore: {objects}."),
                           node=node, pdo=name, objects=", ".join(differ))
    return True, Text(N_("Node {node}: {pdo} restored and read back as before (COB-ID 0x{cob}, {count} entries, "
                         "transmission type {type})."), node=node, pdo=name, cob=f"{before.comm.get(1, 0):08X}",
                      count=count_before, type=before.comm.get(2, 255))


async def _restore_sync(session: Session, before: NodeBefore, ctx: WriteContext) -> tuple[bool, str | None]:
    changed = []
    for index, value in before.sync.items():
        if await _read(session, before.node, index, 0) != value:
            await pdo.run_plan(session, before.node, [(f"0x{index:04X}", index, 0, value, 4)],
                               ctx.as_origin(AUDIT_ORIGIN))
            if await _read(session, before.node, index, 0) != value:
                return False, Text(N_("Node {node}: 0x{index} reads back differently after the restore."),
                                   node=before.node, index=f"{index:04X}")
            changed.append(f"0x{index:04X}")
    if changed:
        return True, Text(N_("Node {node}: {objects} had changed during the recording and were written back."),
                          node=before.node, objects=", ".join(changed))
    return True, None


async def restore(session: Session, record: RestoreRecord, ctx: WriteContext,
                  written: Written | None = None) -> tuple[bool, list[str]]:
    """Put every node of ``record`` back; whether all read back as before, and what was done, in words.
    ``written`` (a start that failed halfway, before any NMT start): only the TPDOs it began configuring go back,
    with no check for someone else's remapping; None (a recording that ran, a record left over): all of them,
    checked."""
    good = True
    texts: list[str] = []
    for before in record.nodes:
        try:
            if before.started and written is None:
                await session.nmt(NmtCommand.ENTER_PRE_OPERATIONAL, before.node)
                texts.append(Text(N_("Node {node}: back to pre-operational, as before the recording."),
                                  node=before.node))
            for tpdo in before.tpdos:
                if written is not None and (before.node, tpdo.number) not in written:
                    continue  # this start never touched it
                ok, text = await _restore_tpdo(session, before.node, tpdo, ctx, check_remap=written is None)
                good, texts = good and ok, [*texts, text]
            ok, sync_text = await _restore_sync(session, before, ctx)
            good = good and ok
            texts += [sync_text] if sync_text else []
        except (ProtocolError, DriveBenchError) as exc:
            good = False
            texts.append(Text(N_("Node {node}: not restored ({why}); the restore record is kept for the next try."),
                              node=before.node, why=exc.detail))
    return good, texts


def restore_context() -> WriteContext:
    return WriteContext.internal(user=LOCAL_USER, origin=AUDIT_ORIGIN)


async def restore_leftovers(manager: SessionManager, url: str | None = None) -> list[str]:
    """On server start: restore what recordings the server was killed in left on the nodes (their records), on the
    open session of the record's bus or one opened for it; each result logged. A record that cannot be restored
    now stays for the next start."""
    texts: list[str] = []
    for record_id, record in await asyncio.to_thread(leftovers, url):
        session = next((s for s in manager.list() if str(s.spec) == record.bus), None)
        opened: Session | None = None
        try:
            if session is None:
                session = opened = await manager.open(record.bus)
            for before in record.nodes:
                if before.node not in session.nodes:
                    session.add_node(before.node, before.profile_id)
            ok, done = await restore(session, record, restore_context())
        except DriveBenchError as exc:
            ok, done = False, [Text(N_("The recording's restore record for {bus} was not used: {why}"),
                                    bus=record.bus, why=exc.detail)]
        finally:
            if opened is not None:
                await manager.close(opened.id)
        if ok:
            await asyncio.to_thread(remove, record_id, url)
        for text in done:
            (log.info if ok else log.warning)("scope restore record %s (%s): %s", record_id, record.bus, text)
        texts += done
    return texts
