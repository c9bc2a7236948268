"""The one report of a "New line" wizard run: every step's state and result in words, and per planned node the
device that took it (the HTML page and the JSON download show the same)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel

from drivebench.i18n import _
from drivebench.services.line.project import LineProject
from drivebench.services.line.wizard_run import STEP_TITLES, STEPS, WizardRun


class ReportStep(BaseModel):
    step: str
    number: int
    title: str
    state: str
    lines: list[str]
    finished: datetime | None


class ReportNode(BaseModel):
    node_id: int
    name: str
    device: str
    serial: str | None
    """The serial of the found device that took the node ID (None: not addressed by this run)."""
    firmware_version: str | None


class WizardReport(BaseModel):
    title: str
    run_id: int
    session_id: str
    project: str
    project_id: int | None
    created_by: str
    created: datetime | None
    updated: datetime | None
    complete: bool
    verdict: str
    steps: list[ReportStep]
    nodes: list[ReportNode]


def report(run: WizardRun, project: LineProject | None) -> WizardReport:
    steps = [ReportStep(step=name, number=number, title=_(STEP_TITLES[name]), state=run.step(name).state,
                        lines=run.step(name).lines, finished=run.step(name).finished)
             for number, name in enumerate(STEPS, start=1)]
    failed = [step.title for step in steps if step.state in ("failed", "interrupted")]
    open_ = [step.title for step in steps if step.state in ("pending", "running")]
    if run.complete:
        verdict = _("The line is commissioned: every step is done.")
    elif failed:
        verdict = _("Not done: {steps} failed.").format(steps=", ".join(failed))
    else:
        verdict = _("Not done yet: {steps} still to run.").format(steps=", ".join(open_))
    nodes = [ReportNode(node_id=node.node_id, name=node.name, device=node.device,
                        serial=run.assigned[node.node_id].serial if node.node_id in run.assigned else None,
                        firmware_version=node.firmware_version)
             for node in (project.nodes if project else [])]
    return WizardReport(title=_("New line: commissioning report"), run_id=run.id, session_id=run.session_id,
                        project=run.project_name, project_id=run.project_id, created_by=run.created_by,
                        created=run.created, updated=run.updated, complete=run.complete, verdict=verdict,
                        steps=steps, nodes=nodes)
