"""Which server process runs a step of a wizard run, kept in the run's row (``line_wizard_run.step_*``, migration
0014_wizard_step_claim), so every server of the database sees it: one step of a run at a time, across servers.

A claim is taken by one compare-and-set UPDATE (only the request that finds the claim as it read it wins, on SQLite
and PostgreSQL alike), carries the holder (host:pid) and a lease the holder renews while the step runs, and is given
back with the step's result. A claim whose lease has passed, or whose holder is a process of this machine that no
longer exists, is no claim: the step it names was cut off and reads ``interrupted``."""

from __future__ import annotations

import asyncio
import logging
import secrets
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Protocol

from pydantic import BaseModel
from sqlalchemy import ColumnElement, CursorResult, Update, update
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from drivebench.errors import Conflict, DriveBenchError, NotFound
from drivebench.i18n import N_, _
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import LineWizardRow
from drivebench.services.storage.server_process import SERVER, ended

log = logging.getLogger(__name__)
RUNNING_HERE = N_("Step '{step}' of this run is running: wait until it has ended.")
RUNNING_THERE = N_("Step '{step}' of this run is running on another DriveBench server (host {host}, process {pid}) "
                   "since {since}: wait until it has ended (if that server stopped, the step reads interrupted after "
                   "{until}).")
LOST = N_("This server's claim on step '{step}' ran out while the step ran (its lease was not renewed in time) and "
          "another server may have run it since: this result was not kept. Run the step again.")


class StepClaim(BaseModel):
    """The step that runs now, on which server, since when and until when its lease holds."""

    step: str
    server: str
    since: datetime
    until: datetime


@dataclass(frozen=True)
class _Seen:
    token: str | None
    claim: StepClaim | None


def _moment(epoch: float) -> datetime:
    return datetime.fromtimestamp(epoch, UTC)


def _words(moment: datetime) -> str:
    return moment.strftime("%Y-%m-%d %H:%M:%S UTC")


def live_claim(row: LineWizardRow, now: float | None = None) -> StepClaim | None:
    """The row's claim while it holds: its lease has not passed and its holder has not ended."""
    if row.step_claim is None or row.step_name is None or row.step_server is None:
        return None
    until = row.step_lease_until or 0.0
    if until <= (time.time() if now is None else now) or ended(row.step_server):
        return None
    return StepClaim(step=row.step_name, server=row.step_server, since=_moment(row.step_since or until),
                     until=_moment(until))


def refusal(claim: StepClaim, title: str) -> Conflict:
    """The 409 in words: which step runs, on which server and since when."""
    if claim.server == SERVER:
        return Conflict(_(RUNNING_HERE).format(step=title))
    host, _sep, pid = claim.server.rpartition(":")
    return Conflict(_(RUNNING_THERE).format(step=title, host=host, pid=pid, since=_words(claim.since),
                                            until=_words(claim.until)))


def same_claim(token: str | None) -> ColumnElement[bool]:
    """The row still carries the claim ``token`` (None: still none): the condition of every compare-and-set."""
    return LineWizardRow.step_claim.is_(None) if token is None else LineWizardRow.step_claim == token


def changed(db: Session, statement: Update) -> int:
    """Run an UPDATE; how many rows it changed (0: the compare-and-set found the row otherwise)."""
    result = db.execute(statement)
    assert isinstance(result, CursorResult)
    return int(result.rowcount)


def _seen(url: str | None, run_id: int) -> _Seen:
    with transaction(url) as db:  # a read of its own: the UPDATE after it starts a transaction with its write
        row = db.get(LineWizardRow, run_id)
        if row is None:
            raise NotFound(_("Wizard run {id} does not exist on this session.").format(id=run_id))
        return _Seen(row.step_claim, live_claim(row))


def take(url: str | None, run_id: int, step: str, title: str, lease_s: float) -> str:
    """Claim ``step`` of the run for this process: its token, or the Conflict naming who holds the run now."""
    for _attempt in range(3):
        seen = _seen(url, run_id)
        if seen.claim is not None:
            raise refusal(seen.claim, title)
        token, now = secrets.token_hex(16), time.time()
        with transaction(url) as db:
            won = changed(db, update(LineWizardRow).where(LineWizardRow.id == run_id, same_claim(seen.token)).values(
                step_claim=token, step_name=step, step_server=SERVER, step_since=now,
                step_lease_until=now + lease_s))
        if won == 1:
            return token
    seen = _seen(url, run_id)
    raise refusal(seen.claim, title) if seen.claim is not None else Conflict(_(RUNNING_HERE).format(step=title))


def renew(url: str | None, run_id: int, token: str, lease_s: float) -> bool:
    """Push the lease on; False when the claim is no longer this one's (it ran out and another server took it)."""
    with transaction(url) as db:
        return bool(changed(db, update(LineWizardRow).where(LineWizardRow.id == run_id, same_claim(token))
                            .values(step_lease_until=time.time() + lease_s)))


def lost(title: str) -> Conflict:
    return Conflict(_(LOST).format(step=title))


def released() -> dict[str, None]:
    """The columns that give a claim back."""
    return {"step_claim": None, "step_name": None, "step_server": None, "step_since": None, "step_lease_until": None}


class Renewing(Protocol):
    lease_s: float

    def renew(self, run_id: int, token: str) -> bool: ...


async def keep(store: Renewing, run_id: int, token: str) -> None:
    """Renew the claim every third of its lease while the step runs (a database that does not answer meanwhile is
    tried again at the next turn; a claim another server took is not taken back)."""
    while True:
        await asyncio.sleep(store.lease_s / 3)
        try:
            held = await asyncio.to_thread(store.renew, run_id, token)
        except (SQLAlchemyError, DriveBenchError) as exc:
            log.warning("wizard run %s: the step's claim was not renewed: %s", run_id, exc)
            continue
        if not held:
            log.warning("wizard run %s: the step's claim ran out and was taken by another server", run_id)
            return
