"""How the API and the pages show a job and a read value (``/api/jobs/{id}``, the parameter sets' jobs)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel

from drivebench.i18n import shown
from drivebench.services.params.jobs import Job, Progress
from drivebench.services.params.values import ParameterValue


class ValueOut(BaseModel):
    raw: int | float | str
    value: int | float | str | None
    unit: str | None
    text: str | None
    """Selection-list meaning or the names of the set bits."""


class ParameterValueOut(ValueOut):
    ref: str
    name: str
    index: str
    subindex: int
    display: str
    read_at: float


class IssueOut(BaseModel):
    item: str
    node: int | None
    detail: str
    abort_code: str | None
    abort_text: str | None


class JobOut(BaseModel):
    id: str
    kind: str
    title: str
    state: str
    progress: Progress
    error: str | None
    notes: list[str]
    issues: list[IssueOut]
    result: dict[str, Any] | None = None
    links: dict[str, str]


def value_out(value: ParameterValue) -> ParameterValueOut:
    return ParameterValueOut(ref=value.ref, name=value.name, index=f"0x{value.index:04X}", subindex=value.subindex,
                             raw=value.raw if not isinstance(value.raw, bytes) else value.raw.hex(),
                             value=value.value if not isinstance(value.value, bytes) else value.value.hex(),
                             unit=value.unit, text=value.text, display=value.display, read_at=value.read_at)


def job_out(job: Job, *, with_result: bool = True, root: str = "") -> JobOut:
    result = None
    if with_result:
        values = job.result.get("values", {})
        result = {"values": {node: {ref: value_out(v).model_dump() for ref, v in found.items()}
                             for node, found in values.items()}}
        for retry in ("retried", "failed_after_retry"):  # read-all: asked again at the end / failed again then
            if retry in job.result:
                result[retry] = job.result[retry]
    return JobOut(
        id=job.id, kind=job.kind, title=shown(job.title), state=job.state.value,
        progress=job.progress(), error=job.error and shown(job.error), notes=[shown(note) for note in job.notes],
        issues=[IssueOut(item=i.item, node=i.node, detail=shown(i.detail), abort_code=i.abort_code,
                         abort_text=i.abort_text) for i in job.issues],
        result=result, links={"self": f"{root}/api/jobs/{job.id}", "progress": f"{root}/ws/jobs/{job.id}"})
