"""Guided commissioning: the manuals' first-commissioning sequences, one step at a time, with the telegrams.

The sequences are profile data (``commissioning`` section, :class:`drivebench.device.drive.control.Sequence`): SDO
downloads with the request as the manual prints it, NMT start, process-data telegrams answered by the status word
in TPDO1, and checks of a status word's state or an object's value. A device is offered only the sequences its own
profile carries (and whose ``requires`` objects it has).

Each step records the frames of the node seen on the bus while it ran (both directions) and stops the run with
a message when the answer is not the expected one.

A run belongs to the node and the writer (principal and panel, :mod:`drivebench.services.params.node_lease`) that
started it: asked through another node's address it is not found, another writer may watch it but not run its
steps. Starting it takes the node's write lease; each step runs under it. An SDO step is the one checked write
(:func:`writes.write`: the profile's range, the audit log with the origin ``commissioning``, the lease, the
moving-write check), of the value its bytes hold in the item's data type; a step that can move the drive needs the
confirmation naming its node, given with the request that runs the step.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from dataclasses import dataclass, field
from typing import Protocol

import can
from pydantic import BaseModel

from drivebench import i18n
from drivebench.device.drive import setup402
from drivebench.device.drive.control import Sequence, Step
from drivebench.device.drive.motion import moves, standard_motion
from drivebench.device.profiles.catalog import index_ref
from drivebench.errors import (
    Conflict,
    DriveBenchError,
    InvalidValue,
    NotFound,
    SdoAbortError,
    ServiceError,
    UnknownParameter,
)
from drivebench.i18n import _
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.protocol.datatypes import decode
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control import drive_control, drive_guard
from drivebench.services.params import node_lease, reads, writes
from drivebench.services.params.write_context import WriteContext, Writer

__all__ = ["Run", "RunOut", "Sequence", "Step", "StepWrite", "Wizard", "next_step", "sequences_for", "step_write",
           "wizard"]

ANSWER_TIMEOUT_S = 3.0


class StepValueMissing(InvalidValue):
    """A ``parameter`` step run without a value and without a proposal."""


AUDIT_ORIGIN = "commissioning"
"""The origin of a step's writes in the audit log."""


def sequences_for(node: SessionNode) -> list[Sequence]:
    """The guided sequences this device's profile carries, then for a CiA 402 drive the generic set-up built from
    the standard objects its profile lists (:mod:`drivebench.device.drive.setup402`)."""
    catalog = node.catalog
    if catalog is None:
        return []
    own = [seq for seq in catalog.profile.commissioning
           if all(drive_control.has_ref(catalog, ref) for ref in seq.requires)]
    return [*own, setup402.setup_sequence(catalog.profile)] if setup402.offered(catalog.profile) else own


# --- a run ---------------------------------------------------------------------------------------------------
class Telegram(BaseModel):
    direction: str  # "T" sent by the tool, "R" received
    cob_id: str
    data: str
    t: float


class StepResult(BaseModel):
    number: int
    title: str
    printed: str | None
    telegrams: list[Telegram]
    ok: bool
    message: str


class FieldOut(BaseModel):
    """What the guided form shows for a ``parameter`` step: the parameter as the profile describes it."""

    ref: str
    name: str
    unit: str | None
    min: float | int | None
    max: float | int | None
    default: float | int | str | None
    selection: dict[int, str]
    help: str | None
    source: str | None
    proposal: float | int | str | None


class StepOut(BaseModel):
    number: int
    title: str
    printed: str | None
    moves: bool
    note: str | None
    field: FieldOut | None = None
    """A ``parameter`` step: the parameter it sets and the value the profile proposes."""


class RunOut(BaseModel):
    id: str
    node_id: int
    sequence: str
    title: str
    source: str
    preconditions: list[str]
    missing: list[str]
    """Steps the manual has that the profile cannot offer, with why."""
    steps: list[StepOut]
    position: int
    results: list[StepResult]
    finished: bool
    failed: str | None


_SDO_WITH_MUX = {1, 2, 4, 5, 6}
"""Command specifiers (top three bits) of the SDO frames that carry the multiplexer: initiate download and upload,
abort, block upload and download. Segments carry none: they belong to the transfer open on the channel."""


class _Capture(can.Listener):
    """The frames of one step: its own SDO transfers (the step's objects, told by the multiplexer; segments of such
    a transfer), its NMT command and its process data. Frames of the node the step did not cause (the control
    panel's status poll reading over the same channel, other objects) are not the step's telegrams."""

    def __init__(self, node_id: int, muxes: set[tuple[int, int]], *, nmt: bool = False,
                 pdo: set[int] | None = None) -> None:
        self.node_id = node_id
        self.muxes = muxes
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()
        self._ours = False  # the transfer open on the node's SDO channel is one of the step's
        self.sdo_request, self.sdo_answer = 0x600 + node_id, 0x580 + node_id
        self.pdo = pdo or set()
        self.sent = {self.sdo_request} | {cob for cob in self.pdo if cob & 0x780 in (0x200, 0x300, 0x400, 0x500)}
        if nmt:
            self.sent.add(0x000)

    def _wanted(self, msg: can.Message) -> bool:
        cob, data = msg.arbitration_id, bytes(msg.data)
        if cob == 0x000:
            return 0x000 in self.sent and len(data) >= 2 and data[1] in (0, self.node_id)
        if cob in (self.sdo_request, self.sdo_answer):
            carries_mux = len(data) >= 4 and data[0] >> 5 in _SDO_WITH_MUX
            mux = (int.from_bytes(data[1:3], "little"), data[3]) if carries_mux else None
            if cob == self.sdo_request and mux is not None:
                self._ours = mux in self.muxes
            return self._ours and (mux is None or mux in self.muxes)
        return cob in self.pdo

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            return
        with self._lock:
            if self._wanted(msg):
                self.frames.append(msg)

    def take(self) -> list[can.Message]:
        with self._lock:
            frames, self.frames = self.frames, []
        return frames


def _capture_for(node: SessionNode, step: Step) -> _Capture:
    """What belongs to ``step``: the object it writes or checks, its NMT command, its telegram and the answer."""
    muxes: set[tuple[int, int]] = set()
    if step.kind == "sdo":
        muxes.add((step.index, step.sub))
    refs = [ref for ref in (step.expect_ref, step.ref) if ref]
    fam = drive_control.family(node) if step.kind == "pdo" else None
    if fam is not None:
        refs.append(fam.status_ref)  # read when TPDO1 does not come
    for ref in refs:
        found = _mux_of(node, ref)
        if found is not None:
            muxes.add(found)
    pdo = {step.cob + node.node_id, 0x180 + node.node_id} if step.kind == "pdo" else None
    return _Capture(node.node_id, muxes, nmt=step.kind == "nmt_start", pdo=pdo)


def _mux_of(node: SessionNode, ref: str) -> tuple[int, int] | None:
    if node.catalog is None:
        return None
    try:
        item = node.catalog.resolve(ref)
    except UnknownParameter:
        return None
    return item.index, item.subindex


@dataclass
class Run:
    id: str
    node_id: int
    sequence: Sequence
    position: int = 0
    results: list[StepResult] = field(default_factory=list)
    failed: str | None = None
    writer: Writer | None = None
    """Who started it (None: a service call without a request); only they run its steps."""
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)

    @property
    def finished(self) -> bool:
        return self.failed is not None or self.position >= len(self.sequence.steps)

    def check_node(self, node_id: int) -> None:
        """Refuse (404) the run asked through another node's address."""
        if node_id != self.node_id:
            raise NotFound(_("Commissioning run {run} belongs to node {owner}, not to node {node}: nothing was sent. "
                             "Open it on node {owner}.").format(run=self.id, owner=self.node_id, node=node_id))

    def check_runner(self, writer: Writer | None) -> None:
        """Refuse (409) a writer other than the one that started the run."""
        if self.writer is None or (writer is not None and writer.same(self.writer)):
            return
        raise Conflict(_("Commissioning run {run} was started by {name} ({where}) on node {node}: only that panel "
                         "runs its steps; this one may watch it.").format(run=self.id, name=self.writer.name,
                                                                          where=_(self.writer.where),
                                                                          node=self.node_id))

    def public(self, node: SessionNode | None = None) -> RunOut:
        seq = self.sequence
        return RunOut(id=self.id, node_id=self.node_id, sequence=seq.key, title=seq.title, source=seq.source,
                      preconditions=list(seq.preconditions), missing=list(seq.missing),
                      steps=[StepOut(number=n + 1, title=s.title, printed=s.printed, moves=s.moves, note=s.note,
                                     field=field_of(node, s) if node is not None else None)
                             for n, s in enumerate(seq.steps)],
                      position=self.position, results=self.results, finished=self.finished, failed=self.failed)


def field_of(node: SessionNode, step: Step) -> FieldOut | None:
    """The form field of a ``parameter`` step (None for other steps and for a parameter the device lacks)."""
    if step.kind != "parameter" or step.ref is None or node.catalog is None:
        return None
    try:
        item = node.catalog.resolve(step.ref)
    except UnknownParameter:
        return None
    entry, language = item.entry, i18n.current()
    helptext = entry.description_de if language == "de" and entry.description_de else entry.description
    return FieldOut(ref=item.ref, name=item.name_for(language), unit=entry.unit, min=entry.min, max=entry.max,
                    default=entry.default, selection=dict(entry.selection), help=helptext, source=entry.source,
                    proposal=step.proposal)


@dataclass(frozen=True)
class StepWrite:
    """What an SDO step writes, as the Parameters tab would: the item's ref and the value in its units."""

    ref: str
    value: object


def step_write(node: SessionNode, step: Step, value: object = None) -> StepWrite:
    """A ``parameter`` step: its parameter and the user's ``value`` (else the profile's proposal; a step without
    either is refused in words). An SDO step: the profile's item at the step's index/subindex and the value of the
    step's bytes in its data type (scaled as the item is); an address the profile does not list is written as the
    bytes."""
    if step.kind == "parameter":
        assert step.ref is not None
        given = step.proposal if value is None or value == "" else value
        if given is None:
            raise StepValueMissing(_("{ref}: this step needs a value (no proposal in the profile); enter it in the "
                                     "form. Nothing was sent.").format(ref=step.ref))
        return StepWrite(step.ref, given)
    item = node.catalog.by_address(step.index, step.sub) if node.catalog is not None else None
    if item is None:
        return StepWrite(index_ref(step.index, step.sub), step.data.hex(" "))
    entry = item.entry
    data_type = entry.data_type
    raw: int | float
    if data_type.is_integer:  # bytes longer than the type give a value it cannot hold: refused in words
        raw = int.from_bytes(step.data, "little", signed=data_type.is_signed and len(step.data) == data_type.size)
    elif data_type.is_float and len(step.data) == data_type.size:
        raw = float(decode(data_type, step.data))
    else:
        return StepWrite(item.ref, step.data.hex(" "))
    return StepWrite(item.ref, raw / entry.factor if entry.factor != 1 else raw)


def step_moves(node: SessionNode, step: Step) -> bool:
    """A step can make the drive move when the sequence says so, when it starts the node (NMT start: the drive acts
    on process data) or when it writes a value the profile (or CiA 402) marks as moving (a command source, the mode
    of operation, a control word that enables)."""
    if step.moves or step.kind == "nmt_start":
        return True
    if step.kind == "parameter":  # judged again with the value given when it runs
        return step.proposal is not None and _writes_moving(node, step_write(node, step))
    if step.kind != "sdo":
        return False
    ref = index_ref(step.index, step.sub)
    try:
        item = node.catalog.resolve(ref) if node.catalog is not None else None
    except UnknownParameter:
        item = None
    if item is None:
        return standard_motion(step.index, step.sub) is not None
    return moves(item, int.from_bytes(step.data, "little"), node.profile) is not None


def _writes_moving(node: SessionNode, write: StepWrite) -> bool:
    try:
        item, raw = writes.checked_raw(node, write.ref, write.value, check=False)
    except DriveBenchError:
        return False
    return isinstance(raw, int) and moves(item, raw, node.profile) is not None


class Wizard:
    def __init__(self) -> None:
        self.runs: dict[str, Run] = {}

    def start(self, session: Session, node: SessionNode, key: str, ctx: WriteContext) -> Run:
        sequence = next((seq for seq in sequences_for(node) if seq.key == key), None)
        if sequence is None:
            raise NotFound(_("No commissioning sequence '{key}' for {device}.").format(key=key,
                                                                                         device=node.device_name))
        sequence = sequence.model_copy(update={"steps": [step.model_copy(update={"moves": step_moves(node, step)})
                                                         for step in sequence.steps]})
        writer = ctx.writer
        table = node_lease.leases(session)
        if writer is None:
            table.check(node.node_id)
        else:  # the run writes the node from its first step to its last: refused while someone else holds it
            table.acquire(node.node_id, writer)
        run = Run(uuid.uuid4().hex[:12], node.node_id, sequence, writer=writer)
        self.runs[run.id] = run
        return run

    def of_node(self, node_id: int) -> list[Run]:
        """The node's runs, the latest first: a reloaded page shows where the last one stands."""
        return [run for run in reversed(self.runs.values()) if run.node_id == node_id]

    def get(self, run_id: str, node_id: int | None = None) -> Run:
        """The run; with ``node_id``, only when it was started for that node."""
        run = self.runs.get(run_id)
        if run is None:
            raise NotFound(_("Commissioning run {run} does not exist (any more).").format(run=run_id))
        if node_id is not None:
            run.check_node(node_id)
        return run


class WizardPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def wizard(self) -> Wizard: ...


def wizard(session: Session) -> Wizard:
    services: WizardPart = session.opened_services()
    return services.wizard


def _telegrams(capture: _Capture, t0: float) -> list[Telegram]:
    return [Telegram(direction="T" if msg.arbitration_id in capture.sent else "R",
                     cob_id=f"0x{msg.arbitration_id:03X}", data=bytes(msg.data).hex(" ").upper(),
                     t=round(max(0.0, msg.timestamp - t0), 4) if msg.timestamp > 1e6 else 0.0)
            for msg in capture.take()]


async def _state_of(session: Session, node: SessionNode, ref: str) -> tuple[str, int]:
    raw = (await reads.read(session, node.node_id, ref)).raw
    word = int(raw) & 0xFFFF if isinstance(raw, int) else 0
    return drive_control.family(node).state_of(word), word


async def _send_and_wait_state(session: Session, node: SessionNode, cob_id: int, data: bytes, expected: str) -> str:
    """Send the RPDO, wait for TPDO1 with the expected state; without one (event TPDO unchanged) read the status
    word. The listener is attached before sending: the drive may answer before ``send`` returns."""
    fam = drive_control.family(node)
    loop = asyncio.get_running_loop()
    found: asyncio.Future[str] = loop.create_future()

    def settle(state: str) -> None:
        if not found.done():
            found.set_result(state)

    class Tpdo(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id == 0x180 + node.node_id and len(msg.data) >= 2:
                state = fam.state_of(int.from_bytes(msg.data[:2], "little"))
                if state == expected:
                    loop.call_soon_threadsafe(settle, state)

    tap = Tpdo()
    session.add_frame_listener(tap)
    try:
        await asyncio.to_thread(frames_of(session.network).send, cob_id, data)
        return await asyncio.wait_for(found, ANSWER_TIMEOUT_S)
    except TimeoutError:
        state, word = await _state_of(session, node, fam.status_ref)
        return state if state == expected else _("{state} (status word 0x{word})").format(state=state,
                                                                                          word=f"{word:04X}")
    finally:
        session.remove_frame_listener(tap)


async def _execute(session: Session, node: SessionNode, step: Step, ctx: WriteContext, value: object = None
                   ) -> str | None:
    """Run one step as ``ctx`` writes; the problem as text, or None when the answer is the expected one."""
    if step.kind == "parameter":
        write = step_write(node, step, value)
        try:
            result = await writes.write(session, node.node_id, write.ref, write.value, ctx=ctx, verify=True)
        except SdoAbortError as exc:
            return _("SDO abort 0x{code} ({text}): {ref} was not written.").format(
                code=f"{exc.abort_code:08X}", text=exc.abort_text, ref=write.ref)
        if result.verified is False:
            return _("{ref} reads back {mismatch}.").format(ref=write.ref, mismatch=result.mismatch or "")
        return None
    if step.kind == "sdo":
        write = step_write(node, step)
        try:
            await writes.write(session, node.node_id, write.ref, write.value, ctx=ctx, verify=False)
        except SdoAbortError as exc:
            return _("SDO abort 0x{code} ({text}) instead of the download response 0x60.").format(
                code=f"{exc.abort_code:08X}", text=exc.abort_text)
        return None
    if step.kind == "nmt_start":
        await session.nmt(NmtCommand.START, node.node_id)
        await asyncio.sleep(0.05)
        return None
    if step.kind == "pdo":
        if step.expect_state is None:
            await asyncio.to_thread(frames_of(session.network).send, step.cob + node.node_id, step.data)
            return None
        state = await _send_and_wait_state(session, node, step.cob + node.node_id, step.data, step.expect_state)
        return None if state == step.expect_state else \
            _("The drive answered '{state}', expected '{expected}'.").format(state=state, expected=step.expect_state)
    assert step.expect_ref is not None
    if step.expect_state is not None:
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while True:
            state, word = await _state_of(session, node, step.expect_ref)
            if state == step.expect_state:
                return None
            if time.monotonic() > deadline:
                return _("{ref} = 0x{word} shows '{state}', expected '{expected}'. Check the preconditions "
                         "(terminals, command source).").format(ref=step.expect_ref, word=f"{word:04X}", state=state,
                                                                expected=step.expect_state)
            await asyncio.sleep(0.05)
    raw = (await reads.read(session, node.node_id, step.expect_ref)).raw
    return None if raw == step.expect_value else _("{ref} = {raw}, expected {expected}.").format(
        ref=step.expect_ref, raw=repr(raw), expected=step.expect_value)


async def next_step(session: Session, node: SessionNode, run: Run, *, ctx: WriteContext, confirm: object = None,
                    panel: drive_control.Panel = drive_control.SERVICE_PANEL, value: object = None) -> Run:
    """Run the next step of ``run`` on its own node, for the writer that started it. The step's value (for a
    ``parameter`` step ``value``, else the profile's proposal) is checked against the profile before anything is
    sent (422 with the range); a step that can move the drive needs ``confirm`` naming the node (428); while
    another panel holds the armed drive, this panel cannot run steps. A ``parameter`` step the device refuses
    (an SDO abort) stays the next step: the user corrects the value and runs it again."""
    run.check_node(node.node_id)
    run.check_runner(ctx.writer)
    async with run.lock:
        if run.finished:
            raise Conflict(_("This commissioning run is finished; start it again to repeat it."))
        step = run.sequence.steps[run.position]
        values = step_values(step, node.node_id)
        moving = step.moves
        if step.kind in ("sdo", "parameter"):  # the profile's range, selection, access: refused before sending
            write = step_write(node, step, value)
            item, raw = writes.checked_raw(node, write.ref, write.value)
            values = writes.sent_values(item, raw)
            if step.kind == "parameter":
                moving = isinstance(raw, int) and moves(item, raw, node.profile) is not None
        guard = drive_control.guard_for(session)
        named = _("Step {number} ({title})").format(number=run.position + 1, title=step.title)
        guard.check(node.node_id, panel, named)
        ctx = ctx.confirming(confirm).as_origin(AUDIT_ORIGIN)
        with node_lease.writing(session, node.node_id, ctx):
            if moving:  # confirmed with the values it sends: the step's write is then admitted as confirmed
                ctx = drive_guard.confirm_moving(session, node.node_id, named, values, ctx)[1]
                if step.kind == "nmt_start":  # as drive_guard.nmt: stays armed until NMT leaves Operational
                    guard.started.add(node.node_id)
                guard.arm(node.node_id, panel, pinned=step.kind == "nmt_start")
            await _run_step(session, node, run, step, ctx, value)
        return run


async def _run_step(session: Session, node: SessionNode, run: Run, step: Step, ctx: WriteContext,
                    value: object = None) -> None:
    capture = _capture_for(node, step)
    session.add_frame_listener(capture)
    t0 = time.time()
    try:
        problem = await _execute(session, node, step, ctx, value)
    except ServiceError:
        raise  # refused (lease, confirmation, holder): nothing of the step was done, the run stays there
    except DriveBenchError as exc:
        problem = exc.shown_detail()
    finally:
        await asyncio.sleep(0.02)  # let the last answer frame reach the capture
        session.remove_frame_listener(capture)
    run.results.append(StepResult(number=run.position + 1, title=step.title, printed=step.printed,
                                  telegrams=_telegrams(capture, t0), ok=problem is None,
                                  message=problem or _("Answer as expected.")))
    if problem is not None and step.kind == "parameter":
        return  # refused by the device: the step stays next, to be run again with another value
    if problem is not None:
        run.failed = _("Stopped at step {number} ({title}): {problem}").format(number=run.position + 1,
                                                                                title=step.title, problem=problem)
    else:
        run.position += 1

def step_values(step: Step, node_id: int) -> dict[str, object]:
    """What a moving NMT or PDO step sends, as its confirmation names it (telegrams in hex, as the manual prints
    them); an SDO step's are those of its checked write (:func:`writes.sent_values`)."""
    if step.kind == "nmt_start":
        return {"NMT": "start"}
    if step.kind == "pdo":
        return {f"COB-ID 0x{step.cob + node_id:03X}": step.data.hex(" ").upper()}
    return {"check": step.expect_ref or ""}
