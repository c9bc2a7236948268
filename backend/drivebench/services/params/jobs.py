"""Long jobs (read-all, parameter-set download): an id, live progress, cancel, and the result kept so far.

A job runs as an asyncio task on the server's event loop; its work function reports progress through
:meth:`Job.advance` and stores what it has so far in ``job.result``. Cancelling stops the work at its next await
and keeps that result. Watchers (the websocket) wait on :meth:`Job.wait_change`.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
import uuid
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from pydantic import BaseModel, ConfigDict

from drivebench import i18n
from drivebench.errors import Conflict, DriveBenchError, NotFound
from drivebench.i18n import _


class JobState(StrEnum):
    RUNNING = "running"
    DONE = "done"
    """Every item handled as asked."""
    INCOMPLETE = "incomplete"
    """Finished, but items were not done (a node stopped answering: ``not_done``), or, for a job that says so
    (a read), some failed."""
    CANCELLED = "cancelled"
    FAILED = "failed"

    @property
    def finished(self) -> bool:
        return self is not JobState.RUNNING


class Progress(BaseModel):
    """How far a job is; the API and the websocket send it as it is."""

    model_config = ConfigDict(frozen=True)

    done: int
    """Items handled: succeeded, failed (``failed``) or given up (``not_done``)."""
    total: int
    failed: int
    not_done: int
    """Items given up without asking (the node stopped answering): neither done nor failed."""
    rate_per_s: float
    """Items per second since the job started."""
    eta_s: float | None
    elapsed_s: float


def said(exc: BaseException) -> str:
    """What an error says, as a ``Text`` where it keeps its N_() template (translated where the job is shown)."""
    if isinstance(exc, DriveBenchError):
        return exc.detail
    return f"{type(exc).__name__}: {exc}"


@dataclass
class JobIssue:
    """One item that failed (an SDO abort, a timeout): the job goes on and reports it."""

    item: str
    detail: str
    node: int | None = None
    abort_code: str | None = None
    abort_text: str | None = None


Work = Callable[["Job"], Awaitable[None]]


@dataclass
class Job:
    id: str
    kind: str
    title: str
    total: int
    state: JobState = JobState.RUNNING
    done: int = 0
    failed: int = 0
    not_done: int = 0
    started_at: float = field(default_factory=time.monotonic)
    created: float = field(default_factory=time.time)
    finished_at: float | None = None
    error: str | None = None
    """Why the job as a whole failed (state ``failed``)."""
    issues: list[JobIssue] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    result: dict[str, Any] = field(default_factory=dict)
    same_as: str | None = None
    failures_leave_incomplete: bool = False
    """A failed item makes the job end ``incomplete`` (a read: the value is missing), not only items not done."""
    concluded: tuple[JobState, str | None] | None = None
    """How the work judged its own end (:meth:`conclude`), instead of the counts."""
    _version: int = 0
    _changed: asyncio.Condition | None = None
    _waiters: int = 0
    _task: asyncio.Task[None] | None = None

    # --- called by the work ---------------------------------------------------------------------------
    def advance(self, count: int = 1, *, issue: JobIssue | None = None) -> None:
        self.done += count
        if issue is not None:
            self.failed += 1
            self.issues.append(issue)
        self._notify()

    def give_up(self, count: int) -> None:
        """``count`` items are left undone (the node fell silent): they count as handled, not as succeeded."""
        self.done += count
        self.not_done += count
        self._notify()

    def conclude(self, state: JobState, error: str | None = None) -> None:
        """The work says how it ended (a download judges by its report: done, incomplete, or failed with why);
        the job finishes so when the work returns."""
        self.concluded = (state, error)

    def add_total(self, count: int) -> None:
        self.total += count
        self._notify()

    # --- watchers ---------------------------------------------------------------------------------------
    def progress(self) -> Progress:
        end = self.finished_at or time.monotonic()
        elapsed = max(end - self.started_at, 1e-9)
        rate = self.done / elapsed
        remaining = max(self.total - self.done, 0)
        eta = None if self.state.finished else (remaining / rate if rate > 0 else None)
        return Progress(done=self.done, total=self.total, failed=self.failed, not_done=self.not_done,
                        rate_per_s=round(rate, 1), eta_s=None if eta is None else round(eta, 1),
                        elapsed_s=round(elapsed, 2))

    @property
    def version(self) -> int:
        return self._version

    async def wait_change(self, since: int, timeout_s: float) -> int:
        """Wait until the job changed after ``since`` (or the timeout); returns the current version."""
        condition = self._condition()
        async with condition:
            if self._version == since and not self.state.finished:
                self._waiters += 1
                try:
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(condition.wait(), timeout_s)
                finally:
                    self._waiters -= 1
        return self._version

    async def wait(self) -> None:
        """Until the job has finished (whatever the outcome)."""
        if self._task is not None:
            await asyncio.wait({self._task})

    def _condition(self) -> asyncio.Condition:
        if self._changed is None:
            self._changed = asyncio.Condition()
        return self._changed

    def _notify(self) -> None:
        self._version += 1
        condition = self._changed
        if condition is None or not self._waiters:
            return

        async def wake() -> None:
            async with condition:
                condition.notify_all()

        asyncio.get_running_loop().create_task(wake())

    def _finish(self, state: JobState, error: str | None = None) -> None:
        self.state = state
        self.error = error
        self.finished_at = time.monotonic()
        self._notify()


class JobManager:
    """The jobs of one server: running ones and the last ``keep`` finished ones."""

    def __init__(self, keep: int = 50) -> None:
        self.keep = keep
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._serial = itertools.count(1)

    def start(self, kind: str, title: str, total: int, work: Work, *, same_as: str | None = None,
              failures_leave_incomplete: bool = False) -> Job:
        """Start ``work(job)`` as a task on the running loop and return the job at once.

        ``same_as`` names what the job does (e.g. which nodes it reads): while a job with the same name runs, that
        job is returned instead of starting another, so repeated requests never queue up work on a node."""
        if same_as is not None:
            running = next((job for job in self._jobs.values()
                            if job.same_as == same_as and not job.state.finished), None)
            if running is not None:
                return running
        job = Job(f"{kind}-{next(self._serial)}-{uuid.uuid4().hex[:6]}", kind, title, total, same_as=same_as,
                  failures_leave_incomplete=failures_leave_incomplete)
        job._task = asyncio.get_running_loop().create_task(self._run(job, work), name=job.id)
        self._jobs[job.id] = job
        self._prune()
        return job

    async def _run(self, job: Job, work: Work) -> None:
        # The task copied the context of the request that started it: its texts are English (or a Text, translated
        # for each reader), never in the language of whoever happened to start it.
        try:
            with i18n.using(i18n.DEFAULT):
                await work(job)
        except asyncio.CancelledError:
            job._finish(JobState.CANCELLED)
            return
        except Exception as exc:  # a failed job reports why; the server keeps running
            job._finish(JobState.FAILED, said(exc))
            return
        if job.concluded is not None:
            job._finish(*job.concluded)
            return
        incomplete = job.not_done or (job.failed and job.failures_leave_incomplete)
        job._finish(JobState.INCOMPLETE if incomplete else JobState.DONE)

    def get(self, job_id: str) -> Job:
        job = self._jobs.get(job_id)
        if job is None:
            raise NotFound(_("No job '{job}' (finished jobs are kept for a while, then dropped)").format(job=job_id))
        return job

    def list(self) -> list[Job]:
        return list(self._jobs.values())

    def cancel(self, job_id: str) -> Job:
        job = self.get(job_id)
        if job.state.finished:
            raise Conflict(_("Job '{job}' has already finished ({state})").format(job=job_id, state=job.state.value))
        if job._task is not None:
            job._task.cancel()
        return job

    def _prune(self) -> None:
        finished = [job_id for job_id, job in self._jobs.items() if job.state.finished]
        for job_id in finished[: max(len(finished) - self.keep, 0)]:
            del self._jobs[job_id]
