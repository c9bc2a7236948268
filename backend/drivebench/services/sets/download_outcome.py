"""How a download (or its retry, or a rollback) ended, judged from its report lines the way a read job is judged
(:class:`~drivebench.services.params.jobs.JobState`): ``done`` when every value went in and was read back,
``incomplete`` when some failed, could not be verified or were not written, ``failed`` when nothing was written
although something should have been."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from pydantic import BaseModel, ConfigDict

from drivebench.i18n import N_, Text
from drivebench.services.params.jobs import JobState

WRITTEN = ("written", "not verified", "mismatch")
"""Report statuses of a write the device confirmed."""
FAILED = ("failed", "mismatch")
"""Report statuses of a value that did not go in as asked (a mismatch was written, but the device holds another)."""
NOT_WRITTEN = ("not attempted",)
"""Report statuses of a value given up without sending it (the node fell silent, the job was cancelled)."""

NOTHING_WRITTEN = N_("Nothing was written: {failed} failed, {not_written} not written")


class DownloadOutcome(BaseModel):
    """The counts a download is judged by (the job API, the stored download and the Sets page show them)."""

    model_config = ConfigDict(frozen=True)

    written: int
    """Writes the device confirmed."""
    verified: int
    """Of those, read back with the set's value."""
    failed: int
    not_written: int

    @property
    def state(self) -> JobState:
        if not self.failed and not self.not_written and self.verified == self.written:
            return JobState.DONE
        if not self.written:
            return JobState.FAILED
        return JobState.INCOMPLETE

    def why_failed(self) -> str | None:
        """The job's error when it failed as a whole."""
        if self.state is not JobState.FAILED:
            return None
        return Text(NOTHING_WRITTEN, failed=self.failed, not_written=self.not_written)


def outcome_of(lines: Iterable[Mapping[str, Any]]) -> DownloadOutcome:
    """The counts of report lines (``status`` as :mod:`~drivebench.services.sets.set_jobs` writes them)."""
    statuses = [line["status"] for line in lines]
    return DownloadOutcome(written=sum(s in WRITTEN for s in statuses), verified=statuses.count("written"),
                           failed=sum(s in FAILED for s in statuses),
                           not_written=sum(s in NOT_WRITTEN for s in statuses))
