"""Safety guard of everything that can move a drive: confirmation, arming, the panel that holds a node, keep-alive
deadlines, the safe stop.

Anything after which a motor may turn (a control word, an RPDO, NMT start) needs an explicit confirmation that names
the node (:func:`require_confirmation`). Once it was sent, the node is *armed*: the panel (browser tab or API client)
that armed it *holds* it until it is disarmed, and must send keep-alives at least every :data:`KEEPALIVE_TIMEOUT_S`
(an API client may ask for up to :data:`MAX_KEEPALIVE_S`). When they stop, or the holder's last websocket closes, the
guard stops the node itself (:meth:`Guard.trip`): cyclic RPDOs to it end, quick stop is written to its control word
(through the guard's own control-word I/O below, so stopping never depends on the panel logic in
:mod:`drivebench.services.control.drive_control`) and, if the tool started it, NMT pre-operational is sent.

Parameter writes go the same way, whatever route sends them (:func:`admit_moving_write`, called by
:func:`writes.write` for what :mod:`drivebench.device.drive.motion` marks as moving): the request's confirmation and
panel come with the write's :class:`~drivebench.services.params.write_context.WriteContext` the web layer builds; the
control panel's own writes, already confirmed and armed, carry it :meth:`~WriteContext.cleared_by_caller`.

A node armed by NMT start or an RPDO stays armed (the status word does not disarm it) until an NMT command that
leaves Operational is sent through the tool, or the guard trips.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
import weakref
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Protocol
from urllib.parse import unquote

from drivebench.errors import ConfirmationRequired, Conflict, DriveBenchError, InvalidValue
from drivebench.i18n import DEFAULT, N_, Text, _, shown, using
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control.drive_words import Command, family_of, next_control_word
from drivebench.services.params import node_lease, reads, session_part, writes
from drivebench.services.params.write_context import (
    SERVICE_PANEL,
    Confirmation,
    Panel,
    Values,
    WriteContext,
)
from drivebench.services.params.write_ports import MovingWrites
from drivebench.services.pdos import process_data as live

KEEPALIVE_TIMEOUT_S = 2.0
STOP_ATTEMPTS = 3
"""Times a command that stops a drive (quick stop, a halt) is sent while its answer does not come (each already with
the session's SDO retries)."""
MAX_KEEPALIVE_S = 10.0
WATCH_PERIOD_S = 0.2
ARM_SETTLE_S = 2.0
"""A status read this soon after arming that finds the drive not enabled does not disarm it (still enabling)."""
log = logging.getLogger(__name__)


def _plain(value: object) -> object:
    """JSON-able and canonical: numbers compared as numbers (2500 == 2500.0), keys as text."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return int(value) if value.is_integer() else value
    if isinstance(value, dict):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return str(value)


def canonical(values: object) -> str:
    return json.dumps(_plain(values), sort_keys=True, separators=(",", ":"), ensure_ascii=False)


def plain_values(values: Values) -> Values:
    plain = _plain(values)
    return plain if isinstance(plain, dict) else {}


def parse_values(text: str | None) -> Values | None:
    """The ``X-DriveBench-Confirm-Values`` header (or form field): a JSON object; None when absent."""
    if text is None or not text.strip():
        return None
    try:
        parsed = json.loads(text)
    except ValueError as exc:
        raise InvalidValue(_("confirm_values is not JSON: {error}").format(error=str(exc)[:80])) from exc
    if parsed is None:  # null: no values, as when absent
        return None
    if not isinstance(parsed, dict):
        raise InvalidValue(_("confirm_values must be a JSON object (what the 428 named), not {kind}.").format(
            kind=type(parsed).__name__))
    return parsed


def _within(given: object, values: Values) -> bool:
    """``values`` are all among the already confirmed ``given`` (a batch or download writing them one by one)."""
    if not isinstance(given, dict):
        return False
    plain = plain_values(given)
    return all(key in plain and canonical(plain[key]) == canonical(item) for key, item in values.items())


def require_confirmation(given: object, node_id: int | None, what: str, values: Values) -> None:
    """``given`` (a :class:`Confirmation` from body fields or the ``X-DriveBench-Confirm`` / ``-Values`` headers)
    must name the node the action moves (its id, or ``all`` for a broadcast: ``node_id`` None) and repeat the
    ``values`` it will send. ``true`` is not enough: a script that confirms everything blindly would confirm the
    wrong node too; and values that differ from what the request sends confirm something else. Inside
    a context the caller cleared (:meth:`WriteContext.cleared_by_caller`) nothing is asked: see
    :func:`confirm_moving`."""
    wanted = "all" if node_id is None else str(node_id)
    node, seen = (given.node, given.values) if isinstance(given, Confirmation) else (given, None)
    text = str(node).strip().lower() if node is not None and node is not False else ""
    same = seen is not None and canonical(seen) == canonical(values)
    if text == wanted and same:
        return
    whom = _("every node of the session") if node_id is None else _("node {node}").format(node=node_id)
    if text == wanted and seen is not None:
        detail = _("{what} lets {whom} move a drive, and the values to send changed since they were confirmed: "
                   "confirm these values (confirm_values).").format(what=what, whom=whom)
    else:
        said = _(" (it said {given})").format(given=repr(str(node)[:20])) if text else ""
        detail = _("{what} lets {whom} move a drive: confirm it with confirm = {wanted} and confirm_values = the "
                   "values named here (or the headers X-DriveBench-Confirm: {plain} and "
                   "X-DriveBench-Confirm-Values){said}.").format(what=what, whom=whom, wanted=repr(wanted),
                                                                  plain=wanted, said=said)
    raise ConfirmationRequired(detail, node="all" if node_id is None else node_id, values=plain_values(values))


def panel_of(host: str | None, panel_id: str | None, operator: str | None) -> Panel:
    """The panel a request or websocket comes from: its id (one per browser tab) or, without one, its host."""
    where = host or Text(N_("an unknown host"))
    name = unquote(operator or "").strip()[:40]  # browsers send it URI-encoded (headers are Latin-1)
    if panel_id:
        who = Text(N_("{name} at {where}"), name=name or Text(N_("panel {id}"), id=panel_id[:6]), where=where)
        return Panel(key=f"panel:{panel_id[:64]}", who=who)
    return Panel(key=f"client:{where}", who=Text(N_("{name} at {where}"), name=name or Text(N_("an API client")),
                                                  where=where))


# --- control-word I/O (shared with drive_control) -------------------------------------------------------------
async def read_word(session: Session, node_id: int, ref: str) -> int:
    raw = (await reads.read(session, node_id, ref)).raw
    if not isinstance(raw, int):
        raise InvalidValue(_("{ref} did not read as an integer word").format(ref=ref))
    return raw & 0xFFFF


async def last_word(session: Session, node_id: int, ref: str) -> int:
    """The control word as the node reads it back; 0 when it cannot (write-only on some devices)."""
    try:
        return await read_word(session, node_id, ref)
    except DriveBenchError:
        return 0


async def write_word(session: Session, node_id: int, ref: str, word: int, ctx: WriteContext) -> None:
    """The callers (control panel, guard) confirmed and armed what moves (``ctx`` cleared), or stop the drive."""
    await writes.write(session, node_id, ref, word & 0xFFFF, ctx=ctx, check=False, verify=False)


async def send_quick_stop(session: Session, node: SessionNode, ctx: WriteContext) -> None:
    """Quick stop to the node's control word, as ``ctx`` stopping (the guard's own :meth:`WriteContext.guard_stop`
    or a panel's): any station may stop a machine, no lease refuses it, and it goes before every read waiting for
    the node."""
    fam = family_of(node.catalog)
    if fam is None:  # the trip skips such nodes (NMT pre-operational is their safe command)
        raise InvalidValue(_("{device} has no device control word DriveBench knows.").format(device=node.device_name))
    async def quick_stop() -> None:
        last = await last_word(session, node.node_id, fam.control_ref)
        await write_word(session, node.node_id, fam.control_ref, next_control_word(fam, Command.QUICK_STOP, last),
                         ctx.stopping())

    with session_part.stop_first(session, node.node_id):
        await sent_until_answered(quick_stop)


async def sent_until_answered(stop: Callable[[], Awaitable[None]]) -> None:
    """Send a command that stops a drive again while its answer does not come, :data:`STOP_ATTEMPTS` times at
    most: a lost or late answer does not leave the drive running (the last failure is raised)."""
    for attempt in range(STOP_ATTEMPTS):
        try:
            await stop()
            return
        except DriveBenchError:
            if attempt == STOP_ATTEMPTS - 1:
                raise


# --- the guard -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Holder:
    panel: Panel
    since: float  # unix time

    def text(self) -> str:
        """Who holds the drive, in the reader's language."""
        return _("{who} since {time}").format(who=shown(self.panel.who),
                                              time=time.strftime("%H:%M:%S", time.localtime(self.since)))


class Guard:
    """Armed nodes of one session: who holds each, the keep-alive deadlines, the open panels; quick stop when the
    holder's keep-alive stops or its last panel closes."""

    def __init__(self, session: Session) -> None:
        self._session = weakref.ref(session)
        self.deadlines: dict[int, float] = {}
        self.holders: dict[int, Holder] = {}
        self.armed_at: dict[int, float] = {}
        self.trips: dict[int, str] = {}
        """The last stop of each node (a :class:`~drivebench.i18n.Text`: shown in the reader's language)."""
        self.sockets: dict[tuple[int, str], int] = {}
        self.clients: dict[str, int] = {}
        """Open keep-alive sockets of each panel (a page's session-wide keep-alive, not a control panel)."""
        self.timeouts: dict[int, float] = {}
        self.pinned: set[int] = set()
        """Armed by NMT start or an RPDO: the status word does not disarm these."""
        self.started: set[int] = set()
        """Started by the tool (NMT start): the trip sends them NMT pre-operational."""
        self.orphaned: dict[int, str] = {}
        """Nodes whose holding page closed (who it was), stopped at their deadline unless the tab comes back."""
        self._task: asyncio.Task[None] | None = None

    def armed(self, node_id: int) -> bool:
        return node_id in self.deadlines

    def holder(self, node_id: int) -> Holder | None:
        return self.holders.get(node_id) if node_id in self.deadlines else None

    def check(self, node_id: int, panel: Panel, what: str) -> None:
        """Refuse ``what`` when another panel holds the armed node."""
        holder = self.holder(node_id)
        if holder is not None and holder.panel.key != panel.key:
            raise Conflict(_("{what} refused: node {node} is held by {holder}. This panel watches: it can stop the "
                             "drive (quick stop, disable) but not move it.").format(what=what, node=node_id,
                                                                                    holder=holder.text()))

    def arm(self, node_id: int, panel: Panel = SERVICE_PANEL, *, pinned: bool = False,
            timeout_s: float | None = None) -> None:
        """``timeout_s``: the keep-alive deadline, :data:`KEEPALIVE_TIMEOUT_S` as it is when the node is armed."""
        self.check(node_id, panel, _("Arming"))
        timeout = KEEPALIVE_TIMEOUT_S if timeout_s is None else timeout_s
        if self.holder(node_id) is None:
            self.holders[node_id] = Holder(panel, time.time())
            self.timeouts[node_id] = timeout
        else:
            self.timeouts[node_id] = max(timeout, self.timeouts.get(node_id, KEEPALIVE_TIMEOUT_S))
        if pinned:
            self.pinned.add(node_id)
        self.armed_at[node_id] = time.monotonic()
        self.deadlines[node_id] = time.monotonic() + self.timeouts[node_id]
        self.trips.pop(node_id, None)
        self._ensure_watch()

    def keepalive(self, node_id: int, panel: Panel = SERVICE_PANEL) -> bool:
        """Restart the deadline if ``panel`` holds the node (a watcher's keep-alive keeps nothing alive); the
        holder's write lease on the node is renewed with it."""
        holder = self.holder(node_id)
        if holder is None or holder.panel.key != panel.key:
            return False
        self.orphaned.pop(node_id, None)
        self.deadlines[node_id] = time.monotonic() + self.timeouts.get(node_id, KEEPALIVE_TIMEOUT_S)
        session = self._session()
        if session is not None:
            node_lease.leases(session).renew(node_id, panel.key)
        return True

    def held_by(self, panel: Panel) -> list[int]:
        return sorted(node for node, holder in self.holders.items() if node in self.deadlines
                      and holder.panel.key == panel.key)

    def trip_text(self, node_id: int) -> str | None:
        """The node's last stop in the reader's language."""
        trip = self.trips.get(node_id)
        return shown(trip) if trip is not None else None

    def held_elsewhere(self, panel: Panel) -> dict[int, str]:
        """Armed nodes another panel holds (their holder): a keep-alive of ``panel`` does not reach them."""
        return {node: holder.text() for node, holder in sorted(self.holders.items())
                if node in self.deadlines and holder.panel.key != panel.key}

    def keepalive_all(self, panel: Panel) -> list[int]:
        """A page's session-wide keep-alive: every node ``panel`` holds."""
        return [node for node in self.held_by(panel) if self.keepalive(node, panel)]

    def release(self, node_id: int, armed_before: float | None = None, *, nmt: bool = False) -> None:
        """Disarm; with ``armed_before``, only if the last arming happened before that (monotonic) time. A node
        armed by NMT start or an RPDO is disarmed only by an NMT command (``nmt``) that leaves Operational."""
        if armed_before is not None and self.armed_at.get(node_id, 0.0) >= armed_before:
            return
        if node_id in self.pinned and not nmt:
            return
        self.pinned.discard(node_id)
        if nmt:
            self.started.discard(node_id)
        self.deadlines.pop(node_id, None)
        self.holders.pop(node_id, None)

    def panels(self, node_id: int) -> int:
        return sum(count for (node, _), count in self.sockets.items() if node == node_id)

    def opened(self, node_id: int, panel: Panel) -> None:
        key = (node_id, panel.key)
        self.sockets[key] = self.sockets.get(key, 0) + 1

    def closed(self, node_id: int, panel: Panel) -> bool:
        """A panel's websocket closed: True when it was the holder's last one (then the node must quick stop)."""
        key = (node_id, panel.key)
        left = self.sockets.get(key, 1) - 1
        if left > 0:
            self.sockets[key] = left
            return False
        self.sockets.pop(key, None)
        holder = self.holder(node_id)
        return holder is not None and holder.panel.key == panel.key

    def client_opened(self, panel: Panel) -> None:
        self.clients[panel.key] = self.clients.get(panel.key, 0) + 1

    def client_closed(self, panel: Panel) -> list[int]:
        """A page's keep-alive socket closed: the nodes it held with no other socket of it left open. They stop at
        their deadline (at most the keep-alive timeout) unless the same tab reconnects first (the next page of an
        in-app navigation, a reload) and keeps them alive."""
        left = self.clients.get(panel.key, 1) - 1
        if left > 0:
            self.clients[panel.key] = left
            return []
        self.clients.pop(panel.key, None)
        orphans = [node for node in self.held_by(panel) if not self.sockets.get((node, panel.key))]
        for node in orphans:
            self.orphaned[node] = panel.who
        return orphans

    async def trip(self, node_id: int, reason: str) -> None:
        """Stop an armed node (keep-alive lost or the holder's panel disconnected): cyclic RPDOs to it end, quick
        stop goes to its control word, and a node the tool started goes to NMT pre-operational. What was done is
        kept as a :class:`~drivebench.i18n.Text` (``reason`` may be one): every reader sees it in their language."""
        with using(DEFAULT):  # a task started by a request carries its language: the record is kept in N_() texts
            await self._trip(node_id, reason)

    async def _trip(self, node_id: int, reason: str) -> None:
        holder = self.holders.pop(node_id, None)
        self.orphaned.pop(node_id, None)
        if self.deadlines.pop(node_id, None) is None:
            return
        self.pinned.discard(node_id)
        started = node_id in self.started
        self.started.discard(node_id)
        session = self._session()
        if session is None or node_id not in session.nodes:
            return
        node = session.nodes[node_id]
        clock = time.strftime("%H:%M:%S")
        has_word = family_of(node.catalog) is not None
        head = Text(N_("Quick stop sent")) if has_word else Text(N_("Safe stop"))
        why = Text(N_("{reason} (held by {who})"), reason=reason, who=holder.panel.who) if holder else reason
        # recorded before the writes return: a status read queued behind them must already name the trip
        self.trips[node_id] = Text(N_("{head} at {clock}: {reason}."), head=head, clock=clock, reason=why)
        stopped = live.service(session).stop_node(node_id)
        steps = [Text(N_("{count} cyclic RPDOs stopped") if stopped != 1 else N_("1 cyclic RPDO stopped"),
                       count=stopped)] if stopped else []
        if has_word:
            try:
                await send_quick_stop(session, node, WriteContext.guard_stop())
            except DriveBenchError as exc:
                head = Text(N_("Quick stop FAILED ({error})"), error=exc.detail)
        if started:
            esm = session.network.capabilities.esm
            try:
                await session.nmt(NmtCommand.ENTER_PRE_OPERATIONAL, node_id)
                steps.append(Text(N_("EtherCAT state Pre-Operational requested") if esm
                                  else N_("NMT pre-operational sent")))
            except DriveBenchError as exc:
                steps.append(Text(N_("EtherCAT state Pre-Operational FAILED ({error})") if esm
                                  else N_("NMT pre-operational FAILED ({error})"), error=exc.detail))
        for step in steps:
            why = Text(N_("{reason}; {step}"), reason=why, step=step)
        self.trips[node_id] = Text(N_("{head} at {clock}: {reason}."), head=head, clock=clock, reason=why)
        log.warning("node %s: %s", node_id, self.trips[node_id])
        session.emit("drive_trip", {"node": node_id, "reason": self.trips[node_id]})

    def moving_writes(self) -> MovingWrites:
        """What :func:`writes.write` asks before a write that can move the drive, and tells after one that stops
        it (the session's part)."""
        return MovingWrites(self._admit_moving_write, self._stopped, self._confirm_moving)

    def _confirm_moving(self, ctx: WriteContext, node_id: int, what: str, values: Values) -> WriteContext:
        session = self._session()
        if session is None:
            raise Conflict(_("The session is closed: nothing was sent."))
        return confirm_moving(session, node_id, what, values, ctx)[1]

    def _admit_moving_write(self, ctx: WriteContext, node_id: int, what: str, values: Values) -> None:
        session = self._session()
        if session is None:
            raise Conflict(_("The session is closed: nothing was sent."))
        admit_moving_write(session, node_id, what, values, ctx)

    def _stopped(self, ctx: WriteContext, node_id: int) -> None:
        session = self._session()
        if session is not None:
            stopped(session, node_id, ctx)

    def close(self) -> None:
        """The session closes: the keep-alive watch ends with it (its bus is gone)."""
        if self._task is not None:
            self._task.cancel()

    def _ensure_watch(self) -> None:
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._watch())

    async def _watch(self) -> None:
        while self.deadlines:
            await asyncio.sleep(WATCH_PERIOD_S)
            now = time.monotonic()
            for node_id, deadline in list(self.deadlines.items()):
                if deadline < now:
                    timeout = self.timeouts.get(node_id, KEEPALIVE_TIMEOUT_S)
                    page = self.orphaned.pop(node_id, None)
                    lost = (N_("the page that started it disconnected (no keep-alive for {seconds} s)") if page
                            else N_("no keep-alive for {seconds} s"))
                    await self.trip(node_id, Text(lost, seconds=f"{timeout:g}"))


class GuardPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def guard(self) -> Guard: ...


def guard_for(session: Session) -> Guard:
    services: GuardPart = session.opened_services()
    return services.guard


# --- writes that can move a drive, by any route (parameter API and tab, set downloads, commissioning) -------------


def confirm_moving(session: Session, node_id: int, what: str, values: Values, ctx: WriteContext
                   ) -> tuple[Panel | None, WriteContext]:
    """``ctx``'s confirmation confirmed ``what`` and the ``values`` it will write (428 without the one naming the
    node and repeating them) and ``ctx``'s panel is no watcher of a node another panel holds (409). The panel (None
    when the caller cleared the context: nothing to check) and the context the operation's writes then carry: an
    operation that will write such values one by one (a batch, a parameter-set download) checks them all before it
    starts, and its writes are admitted as part of what was confirmed."""
    if ctx.cleared:
        return None, ctx
    if ctx.confirmed is None or not _within(ctx.confirmed, values):
        require_confirmation(ctx.confirmation, node_id, what, values)
    guard_for(session).check(node_id, ctx.panel, what)
    return ctx.panel, ctx.with_confirmed({**(ctx.confirmed or {}), **plain_values(values)})


def admit_moving_write(session: Session, node_id: int, what: str, values: Values, ctx: WriteContext) -> None:
    """A write that can make the drive move: confirmed with the values it sends (:func:`confirm_moving`), and it
    arms the node for ``ctx``'s panel, which must keep it alive from now on (or the guard quick-stops it). A context
    without a confirmation (a service's own, the guard's stop) is refused."""
    panel, _confirmed = confirm_moving(session, node_id, what, values, ctx)
    if panel is not None:
        guard_for(session).arm(node_id, panel)


def stopped(session: Session, node_id: int, ctx: WriteContext) -> None:
    """A control word that stops the drive was written (outside the control panel's own logic): disarmed, as the
    panel's shutdown, disable and quick stop disarm."""
    if not ctx.cleared:
        guard_for(session).release(node_id)


# --- NMT and RPDOs: confirmed, armed, stopped by the guard ----------------------------------------------------
def nmt_start_values(targets: list[int], *, broadcast: bool) -> Values:
    """What NMT start sends: the command, and for the broadcast the nodes it starts."""
    return {"NMT": "start", "nodes": targets} if broadcast else {"NMT": "start"}


def rpdo_values(number: int, values: dict[str, str], period_ms: int | None) -> Values:
    """What an RPDO send carries: its number, each mapped object's value as given, the cycle when cyclic."""
    sent: Values = {"RPDO": number, **{ref: value for ref, value in values.items()}}
    if period_ms is not None:
        sent["period [ms]"] = period_ms
    return sent


async def nmt(session: Session, command: NmtCommand, node_id: int, panel: Panel = SERVICE_PANEL, *,
              ctx: WriteContext, confirm: object = None, keepalive: bool = True,
              timeout_s: float = KEEPALIVE_TIMEOUT_S) -> list[int]:
    """Send an NMT command to one node or (``node_id`` 0) to all. Start needs the confirmation naming the node (or
    ``all``), the node's write lease, and arms the started nodes the session knows: ``panel`` must keep them alive
    (every ``timeout_s``) or they are stopped; the leases are ``ctx``'s writer's. ``keepalive=False`` (the caller
    checked it may) arms nothing. Every other command leaves Operational and disarms; it is open to anyone, as
    stopping a machine is."""
    targets = sorted(session.nodes) if node_id == 0 else [session.node(node_id).node_id]
    guard = guard_for(session)
    if command is not NmtCommand.START:
        await session.nmt(command, node_id)
        for target in targets:
            guard.release(target, nmt=True)
        return targets
    require_confirmation(confirm, node_id or None, _("NMT start") if node_id else _("NMT start of all nodes"),
                         nmt_start_values(targets, broadcast=not node_id))
    if not KEEPALIVE_TIMEOUT_S / 4 <= timeout_s <= MAX_KEEPALIVE_S:
        raise InvalidValue(_("The keep-alive timeout must be {low} ... {high} s.").format(
            low=f"{KEEPALIVE_TIMEOUT_S / 4:g}", high=f"{MAX_KEEPALIVE_S:g}"))
    for target in targets:
        guard.check(target, panel, _("NMT start of node {node}").format(node=target))
    with contextlib.ExitStack() as leases:
        for target in targets:
            leases.enter_context(node_lease.writing(session, target, ctx))
        await session.nmt(command, node_id)
    guard.started.update(targets)
    if keepalive:
        for target in targets:
            guard.arm(target, panel, pinned=True, timeout_s=timeout_s)
    return targets


async def send_rpdo(session: Session, node_id: int, number: int, values: dict[str, str], panel: Panel = SERVICE_PANEL,
                    *, ctx: WriteContext, confirm: object = None, owner: str | None = None,
                    period_ms: int | None = None, keepalive: bool = True) -> bytes:
    """Send an RPDO once or (``owner`` and ``period_ms``) cyclically. Needs the confirmation naming the node and
    its write lease (``ctx``'s writer's), and arms the node for ``panel`` (unless ``keepalive`` is off: the caller
    checked it may)."""
    what = _("Sending RPDO{number}").format(number=number)
    require_confirmation(confirm, node_id, what, rpdo_values(number, values, period_ms if owner else None))
    guard = guard_for(session)
    guard.check(node_id, panel, what)
    service = live.service(session)
    with node_lease.writing(session, node_id, ctx):
        if owner is not None and period_ms is not None:
            data = await service.start_cyclic(owner, node_id, number, values, period_ms)
        else:
            data = await service.send_rpdo(node_id, number, values)
    if keepalive:
        guard.arm(node_id, panel, pinned=True)
    return data
