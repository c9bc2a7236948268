"""Batch writes: many values to one node in one request, the way a drive engineer expects a list to be written.

1. Every item is validated first, exactly as a single write validates it (profile range, selection, read-only, the
   data type's width): one invalid item refuses the whole batch (:class:`BatchInvalid`, each item's problem in
   words) and nothing is sent.
2. A batch holding a write that can make the drive move needs the confirmation naming the node, as the single write
   does; without it the whole batch is refused (428) before anything is sent.
3. The items are then written in their order, each through :func:`writes.write` - the single write's own path:
   lease, confirmation and keep-alive arming, one audit row, read-back. The first error the device (or the lease, or
   the guard) reports stops the batch: what was written before stays written and is reported as such, the failing
   item carries its error, the rest is reported as not sent. A read-back that differs is reported, not an error.

The whole batch holds the node's write lease, so no other writer's write lands between two of its items.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from drivebench.device.drive.motion import judge
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session
from drivebench.services.params import node_lease, session_part, writes
from drivebench.services.params.values import WriteResult
from drivebench.services.params.write_context import WriteContext

MAX_BATCH_WRITE = 500
"""Values one batch write may carry (as many as a batch read may name)."""


@dataclass(frozen=True)
class Wanted:
    """One item of a batch: the ref and either the value as the single write takes it or the device's integer."""

    ref: str
    value: object = None
    raw: int | None = None


class BatchInvalid(InvalidValue):
    """Items of a batch write that do not validate; nothing was sent."""

    def __init__(self, problems: list[DriveBenchError | None]) -> None:
        bad = [problem for problem in problems if problem is not None]
        super().__init__(_("{bad} of the {count} values of the batch are not valid, so none was written.").format(
            bad=len(bad), count=len(problems)), hint=N_("Correct the items named in 'items' and send the batch again."))
        self.problems = problems


class State(StrEnum):
    WRITTEN = "written"
    FAILED = "failed"
    NOT_SENT = "not sent"


@dataclass(frozen=True)
class Outcome:
    ref: str
    state: State
    result: WriteResult | None = None
    error: DriveBenchError | None = None


def _validated(session: Session, node_id: int, wanted: Sequence[Wanted], ctx: WriteContext, *, check: bool
               ) -> tuple[list[tuple[object, bool]], WriteContext]:
    """Each item validated as :func:`writes.write` validates it: the value to write, and whether writing it
    stops the drive (a control word that only stops: never refused by the lease); and the context the writes carry
    (with the moving values confirmed). Raises :class:`BatchInvalid`, or the confirmation's 428 / the guard's 409 for
    a moving item, before anything is sent."""
    node = session.node(node_id)
    problems: list[DriveBenchError | None] = []
    moving: list[str] = []
    sent: dict[str, object] = {}
    checked: list[tuple[object, bool]] = []
    for item in wanted:
        try:
            value = writes.given_value(node, item.ref, item.value, item.raw)
            found, raw = writes.checked_raw(node, item.ref, value, check=check)
            writes.encoded(found, raw, value)
        except DriveBenchError as exc:
            problems.append(exc)
            continue
        problems.append(None)
        verdict = judge(found, raw, node.profile)
        if verdict.moving:
            moving.append(f"{found.ref} ({found.name}) = {value}")
            sent.update(writes.sent_values(found, raw))
        checked.append((value, verdict.stopping))
    if any(problems):
        raise BatchInvalid(problems)
    if moving:
        ctx = session_part.service(session).moving_writes.confirm(ctx, node_id, _("Writing {refs}").format(
            refs=", ".join(moving)), sent)
    return checked, ctx


async def write_many(session: Session, node_id: int, wanted: Sequence[Wanted], *, ctx: WriteContext,
                     check: bool = True, verify: bool = True) -> list[Outcome]:
    """Validate all, then write in order and stop at the first error (see the module's text)."""
    if len(wanted) > MAX_BATCH_WRITE:
        raise InvalidValue(_("A batch write carries at most {most} values; this one carries {count}.").format(
            most=MAX_BATCH_WRITE, count=len(wanted)))
    checked, ctx = _validated(session, node_id, wanted, ctx, check=check)
    outcomes: list[Outcome] = []
    stopping_only = all(stopping for _value, stopping in checked)
    with contextlib.nullcontext() if stopping_only else node_lease.writing(session, node_id, ctx):
        for item, (value, _stopping) in zip(wanted, checked, strict=True):
            if outcomes and outcomes[-1].state is not State.WRITTEN:
                outcomes.append(Outcome(item.ref, State.NOT_SENT))
                continue
            try:
                result = await writes.write(session, node_id, item.ref, value, ctx=ctx, check=check,
                                             verify=verify)
            except DriveBenchError as exc:
                outcomes.append(Outcome(item.ref, State.FAILED, error=exc))
            else:
                outcomes.append(Outcome(item.ref, State.WRITTEN, result=result))
    return outcomes
