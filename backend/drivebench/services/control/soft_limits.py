"""Software position limits 0x607D of a standard CiA 402 drive while the panel jogs it, turns it at a velocity
setpoint or moves it by a relative distance.

CiA 402-2: 0x607D.1/.2 are the lowest and highest position (position units, 0/0: none). A drive that supports them
limits the target of a position move to them; in profile velocity (and torque) mode it need not keep to them. One
that does stops at the limit and sets status word bit 11 *internal limit active*. The profile says which kind the
drive is (:class:`~drivebench.device.profiles.profile.SoftwareLimits`):

* the drive clamps: DriveBench lets it, watches, and says so when bit 11 comes with the position at a limit;
* it does not: DriveBench reads the position actual value 0x6064 and velocity 0x606C while the drive moves and
  halts it (velocity modes: setpoint 0; profile position: control word bit 8 *halt*), both stopping with the
  profile deceleration 0x6084, where the braking distance plus what one more read cycle travels reaches the limit.

A relative move whose end lies beyond the limits is refused before it starts, as an absolute target is.
Absolute targets, cyclic setpoints and homing are not watched (the first two are checked against 0x607D when sent;
homing sets the reference the limits count from).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass

from drivebench.device.drive import cia402
from drivebench.errors import DriveBenchError, OutOfRange, ProtocolError
from drivebench.i18n import N_, Text, _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control.drive_guard import last_word, sent_until_answered, write_word
from drivebench.services.control.drive_units import generic_limits, motion_units, position_per_velocity
from drivebench.services.params import reads, writes
from drivebench.services.params.write_context import WriteContext

INTERNAL_LIMIT = 0x0800
"""0x6041 bit 11 *internal limit active*."""
TARGET_REACHED = 0x0400
HALT = 0x0100
"""0x6040 bit 8 *halt*: the drive stops with its profile deceleration (halt option code 0x605D = 1)."""
OPERATION_ENABLED_MASK, OPERATION_ENABLED = 0x006F, 0x0027
CLAMP_WINDOW = 1.0
"""How close (position units) a drive that clamped stands to the limit for DriveBench to call it the limit."""
STAND_S = 5.0
"""How long the watch waits for a halted drive to stand before it describes where it stopped."""
REACTION_S = 0.1
"""The least time DriveBench reckons between reading a position and the drive starting to brake (a read cycle
measured longer counts three times: the cycle that read it, the halt's write, a late next cycle; a wake-up of the
watch measured later than asked counts twice: the server was busy and can be again just before the halt)."""
READ_PAUSE_S = 0.005
"""Between two looks near a limit (the reads themselves take most of a cycle)."""
FAR_PAUSE_S = 0.05
"""At most between two looks while the drive is far from the limit (a quarter of the time it needs to get near)."""
OBSERVE_PAUSE_S = 0.1
"""Between two looks where DriveBench only watches (the drive clamps itself, or the panel released the motion)."""
BLIND_LOOKS = 3
"""Failed looks in a row (reads lost or later than the SDO timeout: a loaded bus or server) after which DriveBench
halts a motion it guards when it knows no speed to reckon with; with one, it reckons where the drive is by now and
halts once that is too close. A look that only watches ends the watch after as many."""
WHAT = {"jog": N_("the jog"), "velocity": N_("the velocity move"), "move": N_("the relative move")}


@dataclass
class Watch:
    """One node's watch: the running task and the last stop at a limit, in words."""

    task: asyncio.Task[None] | None = None
    note: Text | None = None
    released: bool = False
    """The panel ended the motion (jog released, setpoint 0): the watch ends once the drive stands."""


def _watch_of(node: SessionNode) -> Watch:
    found: Watch | None = getattr(node, "_limit_watch", None)  # kept on the node, as its units
    if found is None:
        found = Watch()
        object.__setattr__(node, "_limit_watch", found)
    return found


def note(node: SessionNode) -> str | None:
    """How the last motion ended at a software limit (None: it did not), in the reader's language."""
    text = _watch_of(node).note
    return text.shown() if text is not None else None


async def bounds(session: Session, node: SessionNode) -> tuple[float, float] | None:
    low, high = await generic_limits(session, node, cia402.TARGET_POSITION)
    return (low, high) if low is not None and high is not None else None


async def drive_clamps(session: Session, node: SessionNode) -> bool:
    """The drive keeps inside 0x607D itself (its profile says so, or the object the profile names reads non-zero)."""
    spec = node.catalog.profile.software_limits if node.catalog is not None else None
    if spec is None:
        return False
    if spec.drive_clamps:
        return True
    if spec.clamps_ref is None:
        return False
    try:
        return bool((await reads.read(session, node.node_id, spec.clamps_ref)).raw)
    except DriveBenchError:
        return False


async def _position(session: Session, node: SessionNode) -> float | None:
    value = (await reads.read(session, node.node_id, cia402.POSITION_ACTUAL_VALUE)).value
    return float(value) if isinstance(value, (int, float)) else None


async def check_relative(session: Session, node: SessionNode, distance: float) -> None:
    """Refuse a relative move from the position actual value whose end lies beyond 0x607D."""
    limits = await bounds(session, node)
    position = await _position(session, node) if limits is not None else None
    if limits is None or position is None:
        return
    end = position + distance
    if limits[0] <= end <= limits[1]:
        return
    unit = (await motion_units(session, node)).position
    raise OutOfRange(_("A relative move of {distance} {unit} from {position} {unit} would end at {end} {unit}, "
                       "outside the software position limits 0x607D {low} ... {high} {unit}.").format(
        distance=f"{distance:g}", position=f"{position:g}", end=f"{end:g}", low=f"{limits[0]:g}",
        high=f"{limits[1]:g}", unit=unit))


def start(session: Session, node: SessionNode, what: str, ctx: WriteContext) -> None:
    """Watch the motion ``what`` ("jog", "velocity", "move") just started by ``ctx`` (a watch already running ends
    first); its halt is ``ctx``'s, stopping."""
    old = _watch_of(node)
    if old.task is not None and not old.task.done():
        old.task.cancel()
    watch = Watch()
    object.__setattr__(node, "_limit_watch", watch)
    watch.task = asyncio.get_running_loop().create_task(_run(session, node, what, watch, ctx))


def stop(node: SessionNode) -> None:
    """The panel ended the motion (jog released, setpoint 0): the watch ends once the drive stands, and says
    whether the drive clamped on the way (a release often comes just as it does)."""
    _watch_of(node).released = True


@dataclass
class _Sample:
    word: int
    position: float
    velocity: float
    """Position units per second."""


async def _sample(session: Session, node: SessionNode, per_velocity: float) -> _Sample | None:
    """The drive's status word, position and velocity now (None: one of them could not be read)."""
    found = await reads.read_many(session, node.node_id, [cia402.STATUS_WORD, cia402.POSITION_ACTUAL_VALUE,
                                                               cia402.VELOCITY_ACTUAL_VALUE])
    word, position, velocity = (None if isinstance(one, DriveBenchError) else one.value for one in found)
    if not isinstance(word, int) or not isinstance(position, (int, float)) or not isinstance(velocity, (int, float)):
        return None
    return _Sample(word, float(position), float(velocity) * per_velocity)


async def _number(session: Session, node: SessionNode, ref: str, default: float) -> float:
    try:
        value = (await reads.read(session, node.node_id, ref)).value
    except DriveBenchError:
        return default
    return float(value) if isinstance(value, (int, float)) and value > 0 else default


async def _run(session: Session, node: SessionNode, what: str, watch: Watch, ctx: WriteContext) -> None:
    try:
        await _watch(session, node, what, watch, ctx)
    except DriveBenchError as exc:  # what the watch needs could not be read: a guarded motion does not run on unseen
        if watch.released or watch.note is not None:
            return
        with contextlib.suppress(DriveBenchError):
            await _halt(session, node, 1 if what == "move" else 3, ctx)  # jog and velocity run in mode 3 or 9
            watch.note = Text(N_("DriveBench halted {what}: it could not watch the software limits 0x607D ({error})."),
                              what=Text(WHAT[what]), error=exc.detail)


async def _watch(session: Session, node: SessionNode, what: str, watch: Watch, ctx: WriteContext) -> None:
    limits = await bounds(session, node)
    if limits is None:
        return
    clamps = await drive_clamps(session, node)
    per_velocity = await position_per_velocity(session, node)
    decel = await _number(session, node, cia402.PROFILE_DECELERATION, 0.0) * per_velocity
    unit = (await motion_units(session, node)).position
    mode = (await reads.read(session, node.node_id, cia402.MODES_OF_OPERATION_DISPLAY)).raw
    slowest = 0.0  # the longest read seen: the drive travels that far before DriveBench knows where it is
    latest = 0.0  # the longest a wake-up of this watch came after it was due: a busy server, the drive moves on
    limited = False  # bit 11 seen during this motion
    seen: tuple[_Sample, float] | None = None  # the last sample read and when it was asked for
    blind = 0  # failed looks in a row
    while True:
        asked = time.monotonic()
        sample = await _sample(session, node, per_velocity)
        if sample is not None:  # a failed read's time is reckoned with below, not in every later margin
            slowest = max(slowest, time.monotonic() - asked)
        guarding = not clamps and not watch.released
        pause = OBSERVE_PAUSE_S if not guarding else READ_PAUSE_S
        if sample is None:
            blind += 1
            if not (guarding and seen is not None and seen[0].velocity):  # no speed to reckon with
                if blind < BLIND_LOOKS:
                    await asyncio.sleep(pause)
                    continue
                if guarding:
                    raise ProtocolError(Text(N_("{count} reads of the position in a row failed"), count=blind))
                return
            last, last_asked = seen  # reckon where the drive is by now from where it was and how fast it went
            sample = _Sample(last.word, last.position + last.velocity * (asked - last_asked), last.velocity)
        else:
            blind, seen = 0, (sample, asked)
        if sample.word & OPERATION_ENABLED_MASK != OPERATION_ENABLED:
            return
        edge = limits[1] if sample.velocity > 0 else limits[0]
        at = min(limits, key=lambda limit: abs(sample.position - limit))
        limited = limited or bool(sample.word & INTERNAL_LIMIT)
        if clamps:
            held = sample.word & INTERNAL_LIMIT and abs(sample.position - at) <= CLAMP_WINDOW
            if held or (limited and watch.released and not sample.velocity):
                watch.note = Text(N_("Stopped at the software limit {limit} {unit}: the drive clamped (0x6041 bit "
                                     "11 internal limit active)."), limit=f"{at:+g}", unit=unit)
                return
        elif sample.velocity and not watch.released:
            sign = 1.0 if sample.velocity > 0 else -1.0
            speed = abs(sample.velocity)
            room = (edge - sample.position) * sign - speed * (time.monotonic() - asked)  # where it is by now
            braking = speed * speed / (2 * decel) if decel else speed * 1.0
            margin = room - braking - speed * max(REACTION_S, 3 * slowest, 2 * latest)
            pause = min(FAR_PAUSE_S, max(READ_PAUSE_S, margin / speed / 4))  # far from it: fewer reads on the bus
            if margin <= 0:
                await _halt(session, node, mode, ctx)
                stood = await _stood(session, node, per_velocity)
                short = (edge - stood) * sign if stood is not None else room
                said = (N_("DriveBench halted {what} {gap} {unit} before the software limit {limit} {unit} (0x607D; "
                           "the drive does not clamp there itself), with the profile deceleration 0x6084.")
                        if short >= 0 else  # the halt's answer was lost or late, and the drive ran on meanwhile
                        N_("DriveBench halted {what}, but it stood {gap} {unit} past the software limit {limit} "
                           "{unit}: the halt was answered late (0x607D; the drive does not clamp there itself)."))
                watch.note = Text(said, what=Text(WHAT[what]), gap=f"{abs(short):.4g}", limit=f"{edge:+g}", unit=unit)
                return
        if not sample.velocity and (watch.released or (what == "move" and sample.word & TARGET_REACHED)):
            return
        due = time.monotonic() + pause
        await asyncio.sleep(pause)
        latest = max(latest, time.monotonic() - due)


async def _halt(session: Session, node: SessionNode, mode: object, ctx: WriteContext) -> None:
    """Velocity modes: setpoint 0 (the drive ramps down with 0x6084); other modes: control word bit 8 halt (not a
    still word: it is the confirmed motion's own halt, cleared by the caller)."""
    halt = ctx.cleared_by_caller().stopping()  # stopping a drive is never refused

    async def send() -> None:
        if mode in (3, 9):
            await writes.write(session, node.node_id, cia402.TARGET_VELOCITY, 0, ctx=halt, verify=False)
        else:
            word = await last_word(session, node.node_id, cia402.CONTROL_WORD)
            await write_word(session, node.node_id, cia402.CONTROL_WORD, word | HALT, halt)
    await sent_until_answered(send)  # sent again while its answer does not come


async def _stood(session: Session, node: SessionNode, per_velocity: float) -> float | None:
    """The position once the drive stands (None: it did not within :data:`STAND_S`)."""
    deadline = time.monotonic() + STAND_S
    while time.monotonic() < deadline:
        sample = await _sample(session, node, per_velocity)
        if sample is not None and not sample.velocity:
            return sample.position
        await asyncio.sleep(0.01)
    return None
