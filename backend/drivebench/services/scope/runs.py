"""A scope run: one recording of a session at a time, from start to its stored capture, watched live by any number
of viewers.

The run feeds every frame of its source to the trigger engine and to its watchers (each watcher takes what came
since it last looked: the socket sends it in batches). The session's EMCYs and NMT changes (its EMCY and heartbeat
feeds) and the source's own events become markers of the recorded nodes and may trigger. A single capture ends the
run and is stored; in free run and normal mode the run goes on, each complete capture replacing the last, until
Stop stores the last one (or, with none complete, what the capture holds so far).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
import uuid
import weakref
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Literal

from drivebench.errors import Conflict, DriveBenchError, InvalidValue, NotFound
from drivebench.i18n import DEFAULT, N_, Text, _, shown, using
from drivebench.protocol.canopen.heartbeat import HeartbeatStatus
from drivebench.protocol.emcy import EmcyEvent
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_guard import confirm_moving, require_confirmation
from drivebench.services.control.drive_words import Family, family_of, state_text
from drivebench.services.params.write_context import WriteContext
from drivebench.services.scope import store
from drivebench.services.scope.channels import ChannelInfo, describe
from drivebench.services.scope.source import ScopeChannel, ScopeEvent, ScopeFrame, ScopeSource
from drivebench.services.scope.sources import SOURCE_NAMES, moving_steps, open_source, parts
from drivebench.services.scope.trigger import Capture, Sample, TriggerEngine, TriggerSpec, markers

State = Literal["armed", "recording", "done", "stopped", "failed"]
LIVE_KEPT = 2000
"""Samples a viewer who opens the page during a run gets first."""
MIN_PERIOD_S, MAX_PERIOD_S = 0.001, 10.0
MAX_LENGTH = 200_000
OWNER_GRACE_S = 3.0
"""A recording that changed nodes ends this long after its owner's last page closed (a reload comes back sooner)."""
DEFAULT_MAX_S, MAX_MAX_S = 600.0, 86_400.0
"""How long a recording runs with no page of its owner open (``max_s`` at start; an API client's run ends by itself
after it, a page's runs on while the page is open)."""
ABANDON_CHECK_S = 1.0


@dataclass
class Watcher:
    rows: list[list[Any]] = field(default_factory=list)
    events: list[ScopeEvent] = field(default_factory=list)
    """The events since the watcher last looked (:func:`event_json` puts each into the watcher's language)."""
    changed: bool = True
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    user: str | None = None


def _row(sample: Sample) -> list[Any]:
    return [sample.sample, round(sample.time_s, 6), *sample.values]


def event_json(event: ScopeEvent) -> dict[str, Any]:
    """A marker as a viewer gets it: its text in the viewer's language (the current one)."""
    return {"time_s": round(event.time_s, 6), "node": event.node, "kind": event.kind, "text": shown(event.text)}


class ScopeRun:
    def __init__(self, session: Session, infos: list[ChannelInfo], spec: TriggerSpec, source: ScopeSource,
                 user: str, name: str, max_s: float = DEFAULT_MAX_S) -> None:
        self.id = uuid.uuid4().hex[:12]
        self.session = session
        self.infos = infos
        self.spec = spec
        self.source = source
        self.user = user
        self.name = name
        self.state: State = "armed" if spec.mode != "free" else "recording"
        self.engine = TriggerEngine(spec, len(infos))
        self.live: deque[list[Any]] = deque(maxlen=LIVE_KEPT)
        self.events: list[ScopeEvent] = []
        self.capture: Capture | None = None
        self.recording_id: int | None = None
        self.restored: list[str] = []
        """What the stop put back, in words (:class:`~drivebench.i18n.Text` where DriveBench made them: each reader
        gets them in their language, :meth:`status`)."""
        self.error: str | None = None
        self.started = time.monotonic()
        self.watchers: dict[str, Watcher] = {}
        self._nodes = {info.channel.node for info in infos}
        self._finishing: asyncio.Task[None] | None = None
        self._closing = False
        self._draining = False
        self._status_words = status_words(session, infos)
        self._drive_states: dict[int, str] = {}
        self._owner_left: asyncio.Task[None] | None = None
        self.max_s = max_s
        self._abandoned: asyncio.Task[None] | None = None

    # --- what the source and the session deliver ------------------------------------------------------------------
    def on_frame(self, frame: ScopeFrame) -> None:
        """A frame of the source; while it stops (:meth:`finish`) the frames it still delivers, up to the last SYNC
        sent before Stop, are kept too: the recording ends where it was stopped."""
        if self.state not in ("armed", "recording") or (self._closing and (not self._draining or self.engine.done)):
            return
        self._drive_state_markers(frame)
        sample = Sample(frame.sample, frame.time_s, tuple(
            info.value(raw) for info, raw in zip(self.infos, frame.raw, strict=False)))
        row = _row(sample)
        self.live.append(row)
        for watcher in self.watchers.values():
            watcher.rows.append(row)
            watcher.wake.set()
        was_armed = self.engine.armed
        capture = self.engine.feed(sample)
        if was_armed and not self.engine.armed:
            self.state = "recording"
            self._changed()
        if capture is not None:
            self.capture = capture
            self._changed()
            if self._closing:
                return
            if self.engine.done:
                self._finishing = asyncio.create_task(self.finish("done"))
            elif self.spec.mode == "normal":
                self.state = "armed"

    def on_event(self, event: ScopeEvent) -> None:
        self.engine.event(event)
        if event.node is None or event.node in self._nodes or event.kind == "source":
            self.events.append(event)
            for watcher in self.watchers.values():
                watcher.events.append(event)
                watcher.wake.set()

    def _drive_state_markers(self, frame: ScopeFrame) -> None:
        """A recorded status word whose device state changed: a marker naming the new state."""
        for position, family in self._status_words.items():
            raw = frame.raw[position] if position < len(frame.raw) else None
            if raw is None:
                continue
            key = family.state_of(raw)
            before = self._drive_states.get(position)
            self._drive_states[position] = key
            if before is not None and key != before:
                self.on_event(ScopeEvent(frame.time_s, self.infos[position].channel.node, "drive-state",
                                         state_text(family, key)))

    def session_event(self, node: int, kind: Literal["emcy", "nmt"], text: str) -> None:
        """An EMCY or NMT change of the session, on the samples' time base; none once the run stops (the restore's
        own NMT changes come after the recording's end)."""
        if self._closing:
            return
        self.on_event(ScopeEvent(self.source.elapsed_s(), node, kind, text))

    # --- start and end --------------------------------------------------------------------------------------------
    async def start(self) -> None:
        self.started = time.monotonic()
        await self.source.start(self.on_frame, self.on_event)
        self._abandoned = asyncio.get_running_loop().create_task(self._end_when_abandoned())

    async def _end_when_abandoned(self) -> None:
        """After ``max_s`` with no page of the owner watching (a run started over the API and left), the recording
        ends by itself, stores what it captured and puts the nodes back; an owner's open page keeps it running."""
        while self.state in ("armed", "recording") and not self._closing:
            await asyncio.sleep(ABANDON_CHECK_S)
            if time.monotonic() - self.started >= self.max_s and not self._owner_watches():
                await self.finish("stopped", why=Text(N_(
                    "The recording of {user} reached its maximum length of {seconds} s (max_s, set at start) with "
                    "no page of {user} watching it: it ended by itself."),
                    user=self.user or Text(N_("the owner")), seconds=f"{self.max_s:g}"))
                return

    async def finish(self, state: State, error: str | None = None, why: str | None = None) -> None:
        """Stop the source (it restores what it changed) and store the capture. ``why``: the reason it ended, in
        words, shown first among what was restored. What the stop says is kept as made (Texts, shown to each reader
        in their language); the stop itself speaks English, so that an error's plain detail does not take the
        language of whichever request or task ended the recording."""
        if self._closing or self.state in ("done", "stopped", "failed"):
            return
        if self._abandoned is not None and self._abandoned is not asyncio.current_task():
            self._abandoned.cancel()
        self._closing = True  # no new captures; the state says done/stopped once the capture is stored
        self._draining = True  # what the source delivers while it stops (the SYNCs sent before Stop) is kept
        self.error = error
        try:
            with using(DEFAULT):
                self.restored = [*([why] if why else []), *await self.source.stop()]
        except DriveBenchError as exc:
            self.error = exc.detail
        finally:
            self._draining = False
        capture = self.capture or self.engine.current
        if capture is not None and capture.samples:
            try:
                self.recording_id = await asyncio.to_thread(store.save, self.recording(capture))
            except Exception as exc:  # the database's words reach the page, the run still ends
                self.error = Text(N_("The recording could not be stored: {error}"), error=str(exc))
                state = "failed"
        self.state = state
        self._changed()

    def recording(self, capture: Capture) -> store.Recording:
        columns = store.Columns([s.sample for s in capture.samples], [s.time_s for s in capture.samples],
                                [[s.values[c] for s in capture.samples] for c in range(len(self.infos))])
        trigger = {**self.trigger_json(), "position": capture.trigger, "time_s": capture.trigger_time_s}
        nodes = self.nodes_json()
        return store.Recording(self.name, self.session.id, self.user, self.source.kind, self.source.period_s,
                               [info.as_json() for info in self.infos], trigger,
                               [store.marker(e.time_s, e.node, e.kind, e.text) for e in markers(self.events, capture)],
                               nodes, columns)

    def nodes_json(self) -> dict[str, Any]:
        sets = store.last_downloads(self.session.id, sorted(self._nodes))
        found: dict[str, Any] = {}
        for node_id in sorted(self._nodes):
            node = self.session.node(node_id)
            profile = node.profile
            set_id, version = sets.get(node_id, (None, None))
            found[str(node_id)] = {"device": node.device_name, "profile_id": profile.id if profile else None,
                                   "profile_version": getattr(profile, "version", None) if profile else None,
                                   "parameter_set_id": set_id, "parameter_set_version": version}
        return found

    # --- what the viewers see -------------------------------------------------------------------------------------
    def trigger_json(self) -> dict[str, Any]:
        spec = self.spec
        return {"mode": spec.mode, "on": spec.on, "channel": spec.channel, "edge": spec.edge, "level": spec.level,
                "pre_percent": spec.pre_percent, "length": spec.length, "node": spec.node, "pre": spec.pre}

    def status(self) -> dict[str, Any]:
        period = self.source.period_s
        return {"id": self.id, "state": self.state, "name": self.name, "user": self.user,
                "source": self.source.kind, "source_name": _(SOURCE_NAMES[self.source.kind]),
                "parts": [{**found, "name": _(SOURCE_NAMES[found["kind"]])} for found in parts(self.source)],
                "plan": list(getattr(self.source, "texts", list)()),
                "period_s": period, "rate": round(1 / period, 1) if period else None,
                "channels": [info.as_json() for info in self.infos], "trigger": self.trigger_json(),
                "captures": self.engine.captures, "recording_id": self.recording_id,
                "restored": [shown(text) for text in self.restored],
                "error": shown(self.error) if self.error is not None else None, "max_s": self.max_s}

    def watch(self, user: str | None = None) -> tuple[str, Watcher]:
        key = uuid.uuid4().hex
        watcher = self.watchers[key] = Watcher(rows=list(self.live), events=list(self.events), user=user)
        return key, watcher

    def unwatch(self, key: str) -> None:
        """A page stops watching. The owner's last page gone from a recording that changed nodes (sampling by
        PDO): after :data:`OWNER_GRACE_S` without the owner back, the recording ends and restores them."""
        watcher = self.watchers.pop(key, None)
        if watcher is None or watcher.user != self.user or self.source.kind != "pdo" or self._owner_left:
            return
        if self.state in ("armed", "recording") and not self._owner_watches():
            self._owner_left = asyncio.get_running_loop().create_task(self._end_without_owner())

    def _owner_watches(self) -> bool:
        return any(watcher.user == self.user for watcher in self.watchers.values())

    async def _end_without_owner(self) -> None:
        await asyncio.sleep(OWNER_GRACE_S)
        self._owner_left = None
        if not self._owner_watches():
            await self.finish("stopped", why=Text(N_("The page of {user} closed: the recording ended and put the "
                                                     "nodes back."), user=self.user or Text(N_("the owner"))))

    def _changed(self) -> None:
        for watcher in self.watchers.values():
            watcher.changed = True
            watcher.wake.set()


def status_words(session: Session, infos: list[ChannelInfo]) -> dict[int, Family]:
    """The channels that are a whole status word of their node's device control (position -> its family)."""
    found: dict[int, Family] = {}
    for position, info in enumerate(infos):
        family = family_of(session.node(info.channel.node).catalog)
        if family is None or info.channel.bit is not None:
            continue
        try:
            status = session.node(info.channel.node).catalog.resolve(family.status_ref)  # type: ignore[union-attr]
        except DriveBenchError:
            continue
        if (status.index, status.subindex) == (info.item.index, info.item.subindex):
            found[position] = family
    return found


# --- one run per session ------------------------------------------------------------------------------------------
_runs: weakref.WeakKeyDictionary[Session, ScopeRun] = weakref.WeakKeyDictionary()
_feeds: weakref.WeakKeyDictionary[Session, bool] = weakref.WeakKeyDictionary()


def current(session: Session) -> ScopeRun:
    run = _runs.get(session)
    if run is None:
        raise NotFound(_("No scope recording has run on this session since the server started."))
    return run


def latest(session: Session) -> ScopeRun | None:
    """The session's recording, running or the last one (None: none since the server started)."""
    return _runs.get(session)


def running(session: Session) -> ScopeRun | None:
    run = _runs.get(session)
    return run if run is not None and run.state in ("armed", "recording") else None


def _listen(session: Session) -> None:
    """Subscribe once per session to its EMCY and heartbeat feeds (bus threads; handed to the loop)."""
    if _feeds.get(session):
        return
    _feeds[session] = True
    loop = asyncio.get_running_loop()
    session_ref = weakref.ref(session)

    def deliver(node: int, kind: Literal["emcy", "nmt"], text: str) -> None:
        found = session_ref()
        run = running(found) if found is not None else None
        if run is not None:
            run.session_event(node, kind, text)

    def on_emcy(event: EmcyEvent) -> None:
        text = Text(N_("EMCY {code:04X}h"), code=event.code) if not event.is_reset else Text(N_("EMCY reset"))
        with contextlib.suppress(RuntimeError):  # the loop closed with the server
            loop.call_soon_threadsafe(deliver, event.node_id, "emcy", text)

    def on_heartbeat(status: HeartbeatStatus, kind: str) -> None:
        text = Text(N_("NMT boot-up")) if kind == "bootup" else Text(N_("NMT {state}"), state=Text(
            status.state.label) if status.state is not None else "?")
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(deliver, status.node_id, "nmt", text)

    session.network.emcy.add_callback(on_emcy)
    if (heartbeats := session.heartbeats) is not None:
        heartbeats.add_callback(on_heartbeat)


@dataclass(frozen=True)
class StartRequest:
    channels: list[ScopeChannel]
    period_s: float
    spec: TriggerSpec
    name: str = ""
    max_s: float = DEFAULT_MAX_S


async def start(session: Session, request: StartRequest, user: str, ctx: WriteContext) -> ScopeRun:
    """Start a recording on ``session``; one at a time (a second is refused in words)."""
    if (busy := running(session)) is not None:
        raise Conflict(_("{user} is recording on this session already ({name}); stop that recording first.")
                       .format(user=busy.user or _("someone"), name=busy.name))
    if not MIN_PERIOD_S <= request.period_s <= MAX_PERIOD_S:
        raise InvalidValue(_("The sample period is 1 ms to 10 s, not {period:g} ms.").format(
            period=request.period_s * 1000))
    if not 0 < request.max_s <= MAX_MAX_S:
        raise InvalidValue(_("A recording runs at most {most:g} s without its page (max_s), not {seconds:g} s.")
                           .format(most=MAX_MAX_S, seconds=request.max_s))
    if request.spec.length > MAX_LENGTH:
        raise InvalidValue(_("A capture holds at most {most} samples, not {length}.").format(
            most=MAX_LENGTH, length=request.spec.length))
    infos = await describe(session, request.channels)
    source = await open_source(session, request.channels, request.period_s, ctx)
    for node, what, values in moving_steps(source):  # polling moves nothing; sampling by PDO names its steps
        if node is not None:
            confirm_moving(session, node, what, values, ctx)
        elif not ctx.cleared:  # several nodes: "all"; the source checks each node's guard as it starts
            require_confirmation(ctx.confirmation, None, what, values)
    name = request.name.strip() or _("Recording of {channels}").format(
        channels=", ".join(info.channel.ref for info in infos))
    run = ScopeRun(session, infos, request.spec, source, user, name, request.max_s)
    _listen(session)
    before = _runs.get(session)
    _runs[session] = run
    try:
        await run.start()
    except BaseException:  # refused (a second engineer, a TPDO that would not take the mapping): nothing runs
        if before is not None:
            _runs[session] = before
        else:
            _runs.pop(session, None)
        raise
    return run


async def stop(session: Session) -> ScopeRun:
    run = current(session)
    await run.finish("stopped")
    return run


async def close(session: Session) -> None:
    """The session closes (or the server stops): a running recording ends and keeps what it captured."""
    if (run := running(session)) is not None:
        await run.finish("stopped")
