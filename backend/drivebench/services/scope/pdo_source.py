"""Sampling by PDO: a :class:`~drivebench.services.scope.source.ScopeSource` that maps the plan's free TPDOs
"synchronous, every SYNC", produces the SYNC, and delivers one frame per SYNC with every channel's value from the
TPDO that answered it.

Start: the confirmation (a SYNC producer and NMT start are moving-class: :func:`confirmation`), the node leases
(held for the recording, shared with the same writer's own writes), the restore record in the database, then
each TPDO by the CiA 301 sequence, the NMT start of pre-operational nodes, the SYNC producer. Frames arrive in
the bus thread, are stamped by SYNC count (the last SYNC sent before the bus's timestamp of the frame where the
bus stamps in our clock and the stamp is plausible, else the newest sent: :meth:`PdoScopeSource._stamp`) and handed
to the event loop in batches; the sample of SYNC n is delivered as soon as every sending node answered it (a node
that has not sent yet is waited for until it is silent), at the latest once the producer is :data:`WAIT_S` ahead of
it (a node that sent nothing for it: None). Faults are events in words: a node that stops sending, SYNC paused or
lost, another SYNC producer, bus-off.
Stop: everything back from the record, read back; the record is removed after a good read-back only.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time

import can

from drivebench.errors import Conflict, DriveBenchError
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.control.drive_guard import Values
from drivebench.services.params import node_lease
from drivebench.services.params.write_context import WriteContext
from drivebench.services.pdos import pdo
from drivebench.services.scope import restore_record
from drivebench.services.scope.pdo_plan import SYNC_COB_ID, SYNC_EVERY, PlannedTpdo, ScopePlan
from drivebench.services.scope.source import EventKind, EventSink, FrameSink, ScopeEvent, ScopeFrame, SourceKind
from drivebench.services.scope.sync_producer import SyncProducer
from drivebench.transport.bus import BusSpec

WAIT_S = 1.0
"""How long a sample waits for a TPDO that has not answered it yet (a node, or a loaded machine, that fell behind)."""
SILENT_S = WAIT_S
"""A node that sent none of its TPDOs for this long (and 20 periods) has stopped sending: samples no longer wait
for it."""
TICK_S = 0.02


def confirmation(plan: ScopePlan) -> tuple[int | None, str, Values] | None:
    """What starting the recording must be confirmed with, by the confirmation contract (428 ``confirm_node``,
    ``confirm_values``): the node (None: ``all``, several nodes), what it is and the values; None when the plan
    samples by polling only (no SYNC, no NMT start)."""
    if not plan.tpdos:
        return None
    nodes = plan.pdo_nodes
    values: Values = {"SYNC period [ms]": plan.period_s * 1000, "TPDO nodes": list(nodes),
                      "NMT start": list(plan.start_nodes)}
    what = _("A scope recording by PDO (DriveBench produces SYNC and starts nodes {nodes})").format(
        nodes=", ".join(map(str, plan.start_nodes))) if plan.start_nodes else \
        _("A scope recording by PDO (DriveBench produces SYNC)")
    return (nodes[0] if len(nodes) == 1 else None), what, values


def confirm(session: Session, plan: ScopePlan, ctx: WriteContext) -> None:
    """428 (ConfirmationRequired) unless ``ctx`` confirms :func:`confirmation`; 409 while another panel holds one of
    the nodes in the drive guard."""
    needed = confirmation(plan)
    if needed is None or ctx.cleared:
        return
    node, what, values = needed
    drive_guard.require_confirmation(ctx.confirmation, node, what, values)
    for target in plan.pdo_nodes:
        drive_guard.guard_for(session).check(target, ctx.panel, what)


class _Tap(can.Listener):
    def __init__(self, source: PdoScopeSource) -> None:
        self.source = source

    def on_message_received(self, msg: can.Message) -> None:
        if not msg.is_error_frame and not msg.is_remote_frame and not msg.is_extended_id:
            self.source.on_bus_frame(msg.arbitration_id, bytes(msg.data), msg.timestamp)


class PdoScopeSource:
    kind: SourceKind = "pdo"

    def __init__(self, session: Session, plan: ScopePlan, ctx: WriteContext, *, db_url: str | None = None) -> None:
        self.session = session
        self.plan = plan
        self.ctx = ctx
        self.db_url = db_url
        self.period_s = plan.period_s
        self.record_id: int | None = None
        self.record: restore_record.RestoreRecord | None = None
        self.delivered = 0
        self.late = 0
        """TPDO frames that came after their sample was delivered (counted, not delivered)."""
        self.extra = 0
        """TPDO frames for a SYNC their TPDO had answered already (counted, not delivered)."""
        self._expected: dict[int, int] = {}
        """The SYNC each TPDO (by COB-ID) answers next."""
        self._first: dict[int, int] = {}
        """The SYNC each TPDO's first frame answered."""
        self._cobs = {tpdo.cob_id: tpdo.node for tpdo in plan.tpdos}
        self._host_clock = isinstance(session.spec, BusSpec) and session.spec.stamps_in_host_clock()
        self._producer = SyncProducer(lambda: frames_of(session.network).send(SYNC_COB_ID, b""), plan.period_s)
        self._tap = _Tap(self)
        self._lock = threading.Lock()
        self._pending: list[tuple[int, int, bytes]] = []
        self._foreign_sync = 0
        self._scheduled = False
        self._rows: dict[int, dict[int, bytes]] = {}
        self._next = 0
        self._last_seen: dict[int, float] = {}
        self._silent: set[int] = set()
        self._said: set[str] = set()
        self._leased: list[int] = []
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._on_frame: FrameSink | None = None
        self._on_event: EventSink | None = None
        self._started = 0.0

    # --- start ------------------------------------------------------------------------------------------------
    async def start(self, on_frame: FrameSink, on_event: EventSink) -> None:
        confirm(self.session, self.plan, self.ctx)
        self._on_frame, self._on_event, self._loop = on_frame, on_event, asyncio.get_running_loop()
        if not self.plan.tpdos:
            return
        self._lease()
        written: restore_record.Written = {}
        try:
            self.record = await restore_record.capture(self.session, self.plan)
            self.record_id = await asyncio.to_thread(restore_record.save, self.record, self.db_url)
            for tpdo in self.plan.tpdos:
                written[(tpdo.node, tpdo.number)] = False
                await self._configure(tpdo)
                written[(tpdo.node, tpdo.number)] = True
        except DriveBenchError as exc:  # halfway: what this start wrote goes back now, and the refusal says so
            exc.detail = Text.joined(" ", [exc.detail, *await self._undo(written)])
            raise
        except BaseException:
            await self._undo(written)
            raise
        frames_of(self.session.network).add_listener(self._tap)
        self._started = time.monotonic()
        self._last_seen = dict.fromkeys(self.plan.pdo_nodes, self._started)
        self._producer.start()
        for node in self.plan.start_nodes:
            await self.session.nmt(NmtCommand.START, node)
        self._task = self._loop.create_task(self._watch())

    def _lease(self) -> None:
        writer = self.ctx.writer
        table = node_lease.leases(self.session)
        try:
            for node in self.plan.pdo_nodes:
                if writer is None:
                    table.check(node)
                else:
                    table.acquire(node, writer, hold=True)
                    self._leased.append(node)
        except BaseException:
            self._release()
            raise

    def _release(self) -> None:
        writer = self.ctx.writer
        if writer is not None:
            table = node_lease.leases(self.session)
            for node in self._leased:
                table.done(node, writer)
        self._leased = []

    async def _configure(self, tpdo: PlannedTpdo) -> None:
        assert self.record is not None
        before = next(t for n in self.record.nodes if n.node == tpdo.node for t in n.tpdos if t.number == tpdo.number)
        catalog = pdo.node_catalog(self.session, tpdo.node)
        comm, mapping = pdo.COMM_BASE["tpdo"] + tpdo.number - 1, pdo.MAP_BASE["tpdo"] + tpdo.number - 1
        cob = tpdo.cob_id | (before.comm.get(1, 0) & pdo.COB_NO_RTR)
        steps = [(Text(N_("disable PDO (COB-ID invalid)")), comm, 1, cob | pdo.COB_INVALID, 4),
                 *pdo.mapping_plan(mapping, list(tpdo.entries)),
                 (Text(N_("transmission type")), comm, 2, SYNC_EVERY, 1)]
        if catalog.by_address(comm, 3):
            steps.append((Text(N_("inhibit time")), comm, 3, 0, 2))
        steps.append((Text(N_("enable PDO (COB-ID valid)")), comm, 1, cob, 4))
        done = await pdo.run_plan(self.session, tpdo.node, steps, self.ctx.as_origin(restore_record.AUDIT_ORIGIN))
        if not done[-1].ok:
            step, why = restore_record.failed_step(steps, done)
            raise Conflict(Text(N_("Node {node}: {pdo} could not be set up for the recording: step '{step}' failed "
                                   "({why})."), node=tpdo.node, pdo=tpdo.name, step=step, why=why))

    # --- the bus thread -------------------------------------------------------------------------------------
    def on_bus_frame(self, cob_id: int, data: bytes, timestamp: float | None = None) -> None:
        """``timestamp``: the bus's receive time of the frame (python-can's ``msg.timestamp``)."""
        if cob_id == SYNC_COB_ID:
            with self._lock:
                self._foreign_sync += 1  # a received SYNC is another producer's: ours are sent, not received
            return
        if cob_id not in self._cobs:
            return
        stamp = self._stamp(timestamp)
        with self._lock:
            self._pending.append((stamp, cob_id, data))
            if self._scheduled or self._loop is None:
                return
            self._scheduled = True
        self._loop.call_soon_threadsafe(self._drain)

    def _stamp(self, timestamp: float | None) -> int:
        """The newest SYNC the frame can answer: the last one sent before the bus stamped the frame where that
        timestamp is in our clock (:meth:`BusSpec.stamps_in_host_clock`) and plausible, so that a bus thread that was
        behind when the frame came does not put it late; else (an adapter's own clock or a gateway on another host:
        an offset a 1 ms period cannot afford) the newest SYNC sent when it is taken here."""
        if timestamp is not None and self._host_clock:
            at = self._producer.stamp_at(timestamp, time.time())
            if at is not None:
                return at
        return self._producer.stamp()

    # --- the event loop -------------------------------------------------------------------------------------
    def _drain(self) -> None:
        with self._lock:
            pending, self._pending, self._scheduled = self._pending, [], False
        now = time.monotonic()
        for stamp, cob_id, data in pending:
            sample = self._answered(cob_id, stamp)
            if sample < self._next:
                self.late += 1
                continue
            row = self._rows.setdefault(sample, {})
            if cob_id in row and not self._shift_back(cob_id, sample):
                self.extra += 1  # a second frame for one SYNC: not a synchronous answer (another producer?)
                continue
            row[cob_id] = data
            self._last_seen[self._cobs[cob_id]] = now
        self._deliver(self._next)

    def _shift_back(self, cob_id: int, sample: int) -> bool:
        """A frame for a SYNC its TPDO already answered: the frames before it (not delivered yet) were put one SYNC
        too late (the node was behind when its first frame came); move them one back where there is room."""
        first = sample
        while first - 1 >= self._next and cob_id in self._rows.get(first - 1, {}):
            first -= 1
        if first - 1 < self._next:
            return False
        for number in range(first, sample + 1):
            self._rows.setdefault(number - 1, {})[cob_id] = self._rows[number].pop(cob_id)
        return True

    def _answered(self, cob_id: int, stamp: int) -> int:
        """The SYNC a TPDO frame answers. "Every SYNC" answers each SYNC once, in order: the frame after the one for
        SYNC n answers n + 1, also when it arrives after later SYNCs (a device or a machine that fell behind: its
        answers come in a burst once it gets the CPU again), never one not sent yet (``stamp``: the newest sent
        before the frame was on the bus, :meth:`_stamp`). A node's first frame answers ``stamp``.
        A node whose next SYNC was delivered without it (behind by more than :data:`WAIT_S`, or counted as silent)
        skipped SYNCs (it was killed, restarted): its frame answers ``stamp``. (A device that skips a single
        SYNC looks like one that answers a period late: it stays one SYNC behind.)"""
        expected = self._expected.get(cob_id)
        sample = stamp if expected is None or expected < self._next else min(expected, stamp)
        if expected is None:
            self._first[cob_id] = sample
        self._expected[cob_id] = sample + 1
        return sample

    def _deliver(self, upto: int) -> None:
        """Every sample before ``upto`` (its wait is over), then each one that every sending node answered: a node
        that has not sent yet is waited for until it is silent; no sample before a TPDO's first frame waits for it
        (the node was started after that SYNC), nor one for a silent node."""
        if self._on_frame is None:
            return
        self.period_s = self._producer.period_s
        slots = self.plan.slots
        newest = self._producer.stamp()
        first = {cob: self._first.get(cob, 0) for cob, node in self._cobs.items() if node not in self._silent}
        while self._next < upto or (self._next <= newest and all(
                cob in self._rows.get(self._next, ()) for cob, since in first.items() if since <= self._next)):
            row = self._rows.pop(self._next, {})
            raw = tuple(slot.value(row[slot.cob_id]) if slot is not None and slot.cob_id in row else None
                        for slot in slots)
            self._on_frame(ScopeFrame(self._next, self._next * self.period_s, raw))
            self._next += 1
            self.delivered += 1

    def elapsed_s(self) -> float:
        """The newest SYNC's sample time and the time since it went out, at most one period (an event between two
        SYNCs lies between their samples: the next sample is the first at or after it)."""
        newest, sent = self._producer.stamp(), self._producer.last
        if newest < 0 or sent is None:
            return 0.0
        return newest * self.period_s + min(max(time.monotonic() - sent, 0.0), self.period_s)

    def newest_sync(self) -> int:
        """The number of the newest SYNC sent (-1 before the first)."""
        return self._producer.stamp()

    def _lag(self) -> int:
        """:data:`WAIT_S` in SYNCs."""
        return max(3, math.ceil(WAIT_S / self.plan.period_s))

    def _event(self, node: int | None, text: str, kind: EventKind = "source") -> None:
        """An event of the source at the time of the newest SYNC sent (a sample the recording delivers: also when
        no SYNC follows, SYNC lost or bus-off)."""
        if self._on_event is not None:
            self._on_event(ScopeEvent(max(self._producer.stamp(), 0) * self.period_s, node, kind, text))

    def _once(self, key: str, node: int | None, text: str) -> None:
        if key not in self._said:
            self._said.add(key)
            self._event(node, text)

    async def _watch(self) -> None:
        pauses = 0
        while True:
            await asyncio.sleep(TICK_S)
            self._drain()
            self._deliver(self._producer.stamp() + 1 - self._lag())
            self._check_nodes()
            producer = self._producer
            for number, seconds in producer.pauses[pauses:]:
                self._event(None, Text(N_("SYNC paused for {ms} ms after SYNC {number} (the machine was busy): no "
                                          "samples exist for that time."), ms=f"{seconds * 1000:.0f}", number=number))
            pauses = len(producer.pauses)
            if producer.error:
                self._once("sync-lost", None, Text(N_("SYNC lost: DriveBench could not send it ({why}). The "
                                                      "recording receives no more samples."), why=producer.error))
            if self._foreign_sync:
                self._once("foreign-sync", None, Text(N_("Another device sends SYNC on this bus (COB-ID 0x080) "
                                                         "besides DriveBench: the samples no longer line up by SYNC "
                                                         "count.")))
            if self.session.bus_state == "bus-off":
                self._once("bus-off", None, Text(N_("The CAN adapter is bus-off: no frames are sent or received.")))

    def _check_nodes(self) -> None:
        now = time.monotonic()
        silent_after = max(SILENT_S, 20 * self.plan.period_s)
        for node, seen in self._last_seen.items():
            if now - seen > silent_after and node not in self._silent:
                self._silent.add(node)
                self._event(node, Text(N_("Node {node} stopped sending its TPDOs (none for {ms} ms): its channels "
                                          "are empty from here."), node=node, ms=f"{(now - seen) * 1000:.0f}"))
            elif now - seen <= silent_after and node in self._silent:
                self._silent.discard(node)
                self._event(node, Text(N_("Node {node} sends its TPDOs again."), node=node))

    # --- stop -----------------------------------------------------------------------------------------------
    async def stop(self) -> list[str]:
        if not self.plan.tpdos:
            return []
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        self._producer.stop()
        await self._last_answers()
        self._drain()
        self._deliver(self._producer.count)
        texts: list[str] = [Text(N_("SYNC: {count} sent at a mean period of {period} ms (set: {nominal} ms)."),
                                 count=self._producer.count, period=f"{self._producer.period_s * 1000:.3f}",
                                 nominal=f"{self.plan.period_s * 1000:g}")]
        try:
            return texts + await self._undo()
        finally:
            self._unlisten()

    def _unlisten(self) -> None:
        """Stop taking frames, once the restore has answered: a node answers its SYNCs before the SDO requests sent
        after them, so every answer to a SYNC of the recording has passed the tap by then; one that came after its
        sample went out (a node, or a loaded machine, more than :data:`WAIT_S` behind) is counted as late, not
        lost."""
        frames_of(self.session.network).remove_listener(self._tap)
        self._drain()

    async def _last_answers(self) -> None:
        """Wait until every sending node answered the last SYNC, at most :data:`WAIT_S`, so that the last samples
        carry their values. The count of answers is the source's guess (a node that fell behind may look done one
        frame early): the tap stays until the restore has answered (:meth:`_unlisten`)."""
        last, until = self._producer.count - 1, time.monotonic() + WAIT_S
        while time.monotonic() < until:
            self._drain()
            if all(self._expected[cob] > last for cob, node in self._cobs.items()
                   if cob in self._expected and node not in self._silent):
                return
            await asyncio.sleep(TICK_S)

    async def _undo(self, written: restore_record.Written | None = None) -> list[str]:
        """Everything back from the record; the record removed after a good read-back. ``written``: a start that
        failed halfway, the TPDOs it began (False) or finished (True) configuring: only those go back, and without
        the check for someone else's remapping (their mapping is this start's own half-written one)."""
        self._producer.stop()
        texts: list[str] = []
        try:
            if self.record is not None:
                ok, texts = await restore_record.restore(self.session, self.record, self.ctx, written)
                if ok and self.record_id is not None:
                    await asyncio.to_thread(restore_record.remove, self.record_id, self.db_url)
                    self.record_id = None
                elif not ok:
                    texts.append(Text(N_("The restore record is kept: the next server start tries again.")))
        except DriveBenchError as exc:
            texts.append(Text(N_("The restore failed ({why}); the restore record is kept: the next server start "
                                 "tries again."), why=exc.detail))
        finally:
            self._release()
        return texts
