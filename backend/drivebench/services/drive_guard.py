"""Safety guard of the drive control panels: arming, the panel that holds a drive, keep-alive deadlines, quick stop.

Once a command after which the motor may turn was sent, the node is *armed*: the panel that armed it *holds* it until
it is disarmed, and must send keep-alives at least every :data:`KEEPALIVE_TIMEOUT_S`. When they stop, or the holder's
last websocket closes, the guard sends quick stop itself, through its own control-word I/O (below), so that stopping
never depends on the panel logic in :mod:`drivebench.services.drive_control`.
"""

from __future__ import annotations

import asyncio
import time
import weakref
from dataclasses import dataclass
from urllib.parse import unquote

from drivebench.errors import Conflict, DriveBenchError, InvalidValue
from drivebench.services import parameters
from drivebench.services.drive_words import Command, family_of, next_control_word
from drivebench.services.sessions import Session, SessionNode

KEEPALIVE_TIMEOUT_S = 2.0
WATCH_PERIOD_S = 0.2


@dataclass(frozen=True)
class Panel:
    """Who sends a command: one control panel (browser tab) or one API client. ``key`` identifies it, ``who`` is
    what the other panels are shown."""

    key: str
    who: str


SERVICE_PANEL = Panel("service", "a DriveBench service call")


def panel_of(host: str | None, panel_id: str | None, operator: str | None) -> Panel:
    """The panel a request or websocket comes from: its id (one per browser tab) or, without one, its host."""
    where = host or "an unknown host"
    name = unquote(operator or "").strip()[:40]  # browsers send it URI-encoded (headers are Latin-1)
    if panel_id:
        return Panel(key=f"panel:{panel_id[:64]}", who=f"{name or 'panel ' + panel_id[:6]} at {where}")
    return Panel(key=f"client:{where}", who=f"{name or 'an API client'} at {where}")


# --- control-word I/O (shared with drive_control) -------------------------------------------------------------
async def read_word(session: Session, node_id: int, ref: str) -> int:
    raw = (await parameters.read(session, node_id, ref)).raw
    if not isinstance(raw, int):
        raise InvalidValue(f"{ref} did not read as an integer word")
    return raw & 0xFFFF


async def last_word(session: Session, node_id: int, ref: str) -> int:
    """The control word as the node reads it back; 0 when it cannot (write-only on some devices)."""
    try:
        return await read_word(session, node_id, ref)
    except DriveBenchError:
        return 0


async def write_word(session: Session, node_id: int, ref: str, word: int) -> None:
    await parameters.write(session, node_id, ref, word & 0xFFFF, check=False, verify=False)


async def send_quick_stop(session: Session, node: SessionNode) -> None:
    fam = family_of(node.catalog)
    if fam is None:  # not reached: only nodes with a known control word are ever armed
        raise InvalidValue(f"{node.device_name} has no device control word DriveBench knows.")
    last = await last_word(session, node.node_id, fam.control_ref)
    await write_word(session, node.node_id, fam.control_ref, next_control_word(fam, Command.QUICK_STOP, last))


# --- the guard -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Holder:
    panel: Panel
    since: float  # unix time

    def text(self) -> str:
        return f"{self.panel.who} since {time.strftime('%H:%M:%S', time.localtime(self.since))}"


class Guard:
    """Armed nodes of one session: who holds each, the keep-alive deadlines, the open panels; quick stop when the
    holder's keep-alive stops or its last panel closes."""

    def __init__(self, session: Session) -> None:
        self._session = weakref.ref(session)
        self.deadlines: dict[int, float] = {}
        self.holders: dict[int, Holder] = {}
        self.armed_at: dict[int, float] = {}
        self.trips: dict[int, str] = {}
        self.sockets: dict[tuple[int, str], int] = {}
        self._task: asyncio.Task[None] | None = None

    def armed(self, node_id: int) -> bool:
        return node_id in self.deadlines

    def holder(self, node_id: int) -> Holder | None:
        return self.holders.get(node_id) if node_id in self.deadlines else None

    def check(self, node_id: int, panel: Panel, what: str) -> None:
        """Refuse ``what`` when another panel holds the armed node."""
        holder = self.holder(node_id)
        if holder is not None and holder.panel.key != panel.key:
            raise Conflict(f"{what} refused: node {node_id} is held by {holder.text()}. This panel watches: it can "
                           "stop the drive (quick stop, disable) but not move it.")

    def arm(self, node_id: int, panel: Panel = SERVICE_PANEL) -> None:
        self.check(node_id, panel, "Arming")
        if self.holder(node_id) is None:
            self.holders[node_id] = Holder(panel, time.time())
        self.armed_at[node_id] = time.monotonic()
        self.deadlines[node_id] = time.monotonic() + KEEPALIVE_TIMEOUT_S
        self.trips.pop(node_id, None)
        self._ensure_watch()

    def keepalive(self, node_id: int, panel: Panel = SERVICE_PANEL) -> bool:
        """Restart the deadline if ``panel`` holds the node (a watcher's keep-alive keeps nothing alive)."""
        holder = self.holder(node_id)
        if holder is None or holder.panel.key != panel.key:
            return False
        self.deadlines[node_id] = time.monotonic() + KEEPALIVE_TIMEOUT_S
        return True

    def release(self, node_id: int, armed_before: float | None = None) -> None:
        """Disarm; with ``armed_before``, only if the last arming happened before that (monotonic) time."""
        if armed_before is not None and self.armed_at.get(node_id, 0.0) >= armed_before:
            return
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

    async def trip(self, node_id: int, reason: str) -> None:
        """Quick stop an armed node (keep-alive lost or the holder's panel disconnected)."""
        holder = self.holders.pop(node_id, None)
        if self.deadlines.pop(node_id, None) is None:
            return
        session = self._session()
        if session is None or node_id not in session.nodes:
            return
        node = session.nodes[node_id]
        held = f" (held by {holder.panel.who})" if holder else ""
        # recorded before the write returns: a status read queued behind it must already name the trip
        self.trips[node_id] = f"Quick stop sent at {time.strftime('%H:%M:%S')}: {reason}{held}."
        try:
            await send_quick_stop(session, node)
        except DriveBenchError as exc:
            self.trips[node_id] = f"Quick stop FAILED at {time.strftime('%H:%M:%S')} ({reason}{held}): {exc}"
        session.emit("drive_trip", {"node": node_id, "reason": self.trips[node_id]})

    def _ensure_watch(self) -> None:
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._watch())

    async def _watch(self) -> None:
        while self.deadlines:
            await asyncio.sleep(WATCH_PERIOD_S)
            now = time.monotonic()
            for node_id, deadline in list(self.deadlines.items()):
                if deadline < now:
                    await self.trip(node_id, f"no keep-alive for {KEEPALIVE_TIMEOUT_S:g} s")


_GUARDS: weakref.WeakKeyDictionary[Session, Guard] = weakref.WeakKeyDictionary()


def guard_for(session: Session) -> Guard:
    guard = _GUARDS.get(session)
    if guard is None:
        guard = _GUARDS[session] = Guard(session)
    return guard
