"""A run of the "New line" wizard (issue 32 step 4): one session, one line project, seven steps (scan, assign,
store, boot-up check, parameter sets, program download, report). Each step keeps its state and its result in words;
the devices found and the planned node each is given are kept too. The run lives in the database (table
``line_wizard_run``), so it resumes after a browser reload or a server restart: a step that was running when the
server stopped reads ``interrupted`` and can be run again. Which step runs now, and on which server, is the run's claim
(:mod:`wizard_claim`): every server of the database sees it, and a step whose holder stopped renewing its lease reads
``interrupted``."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Literal

from pydantic import BaseModel, Field
from sqlalchemy import ColumnElement, select, update

from drivebench.config import settings
from drivebench.errors import Conflict, NotFound
from drivebench.i18n import N_, _
from drivebench.protocol.canopen.lss import LssAddress
from drivebench.services.line import wizard_claim
from drivebench.services.line.wizard_claim import StepClaim
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import LineWizardRow

StepName = Literal["scan", "assign", "store", "boot_check", "sets", "program"]
STEPS: tuple[StepName, ...] = ("scan", "assign", "store", "boot_check", "sets", "program")
STEP_TITLES: dict[str, str] = {
    "scan": N_("Scan for unconfigured devices"), "assign": N_("Assign node IDs and bit rate"),
    "store": N_("Store the configuration"), "boot_check": N_("Boot-up check"),
    "sets": N_("Apply the parameter sets"), "program": N_("Program download")}
StepState = Literal["pending", "running", "done", "failed", "interrupted"]
STATE_WORDS: dict[str, str] = {"pending": N_("pending"), "running": N_("running"), "done": N_("done"),
                               "failed": N_("failed"), "interrupted": N_("interrupted")}


class StepResult(BaseModel):
    state: StepState = "pending"
    lines: list[str] = Field(default_factory=list)
    """The step's result in words, one sentence per node or action."""
    finished: datetime | None = None
    runs: int = 0


class FoundDevice(BaseModel):
    """A device the scan found without a node ID (hex text as the LSS page shows it)."""

    vendor: str
    product: str
    revision: str
    serial: str
    device: str | None = None

    def address(self) -> LssAddress:
        return LssAddress(int(self.vendor, 16), int(self.product, 16), int(self.revision, 16), int(self.serial, 16))


class Firmware(BaseModel):
    """A firmware file checked for a node (program download's check): its id while this server holds it."""

    file_id: str
    name: str
    size: int
    crc32: str


def _fresh_steps() -> dict[str, StepResult]:
    return {str(step): StepResult() for step in STEPS}


class WizardRun(BaseModel):
    id: int = 0
    session_id: str
    project_id: int | None
    project_name: str
    created_by: str
    created: datetime | None = None
    updated: datetime | None = None
    steps: dict[str, StepResult] = Field(default_factory=lambda: _fresh_steps())
    found: list[FoundDevice] = Field(default_factory=list)
    assignments: dict[int, str] = Field(default_factory=dict)
    """Planned node ID -> the serial (hex) of the found device it is given."""
    proposed: dict[int, str] = Field(default_factory=dict)
    """What the scan proposed (a serial the project names for the node)."""
    assigned: dict[int, FoundDevice] = Field(default_factory=dict)
    """Node ID -> the device that took it (the store step selects it again by its address)."""
    firmware: dict[int, Firmware] = Field(default_factory=dict)
    claim: StepClaim | None = None
    """The step that runs now, on which server (any server of the database), until when its lease holds."""

    def step(self, name: str) -> StepResult:
        return self.steps.setdefault(name, StepResult())

    @property
    def complete(self) -> bool:
        return all(self.step(name).state == "done" for name in STEPS)


def _aware(moment: datetime) -> datetime:
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


def _of(row: LineWizardRow) -> WizardRun:
    run = WizardRun.model_validate({**row.body, "id": row.id, "session_id": row.session_id,
                                    "project_id": row.project_id, "created_by": row.created_by,
                                    "created": _aware(row.created), "updated": _aware(row.updated)})
    run.claim = wizard_claim.live_claim(row)
    for name, step in run.steps.items():
        if step.state == "running" and (run.claim is None or run.claim.step != name):
            step.state = "interrupted"
            step.lines = [*step.lines, _("The server stopped while this step ran: run it again.")]
    return run


def _body(run: WizardRun) -> dict[str, object]:
    return run.model_dump(mode="json", exclude={"id", "session_id", "project_id", "created_by", "created",
                                                "updated", "claim"})


class WizardStore:
    def __init__(self, url: str | None = None, lease_s: float | None = None) -> None:
        self.url = url
        self.lease_s = settings.wizard_step_lease_s if lease_s is None else lease_s

    def create(self, run: WizardRun) -> WizardRun:
        with transaction(self.url) as db:
            row = LineWizardRow(session_id=run.session_id, project_id=run.project_id, created_by=run.created_by,
                                body=_body(run))
            db.add(row)
            db.flush()
            return _of(row)

    def get(self, run_id: int, session_id: str | None = None) -> WizardRun:
        with transaction(self.url) as db:
            row = db.get(LineWizardRow, run_id)
            if row is None or (session_id is not None and row.session_id != session_id):
                raise NotFound(_("Wizard run {id} does not exist on this session.").format(id=run_id))
            return _of(row)

    def list(self, session_id: str) -> list[WizardRun]:
        with transaction(self.url) as db:
            rows = db.scalars(select(LineWizardRow).where(LineWizardRow.session_id == session_id)
                              .order_by(LineWizardRow.id.desc()))
            return [_of(row) for row in rows]

    def save(self, run: WizardRun) -> WizardRun:
        """Keep a change made outside a step (assignments, a firmware file): refused while a step of the run runs on
        any server, also when one started since ``run`` was read."""
        for _attempt in range(3):
            with transaction(self.url) as db:
                row = db.get(LineWizardRow, run.id)
                if row is None:
                    raise NotFound(_("Wizard run {id} does not exist on this session.").format(id=run.id))
                seen, claim = row.step_claim, wizard_claim.live_claim(row)
            if claim is not None:
                raise wizard_claim.refusal(claim, _(STEP_TITLES.get(claim.step, claim.step)))
            saved = self._write(run, wizard_claim.same_claim(seen), {})
            if saved is not None:
                return saved
        claim = self.get(run.id).claim
        if claim is not None:
            raise wizard_claim.refusal(claim, _(STEP_TITLES.get(claim.step, claim.step)))
        raise Conflict(_("A step of this run started and ended meanwhile: load the run again and repeat the change."))

    def claim(self, run_id: int, step: str) -> str:
        """Take ``step`` of the run for this process (its token), or the 409 naming who runs the run now."""
        return wizard_claim.take(self.url, run_id, step, _(STEP_TITLES.get(step, step)), self.lease_s)

    def renew(self, run_id: int, token: str) -> bool:
        return wizard_claim.renew(self.url, run_id, token, self.lease_s)

    def save_claimed(self, run: WizardRun, step: str, token: str, *, release: bool = False) -> WizardRun:
        """Keep the step's state while this process holds its claim (``release``: and give the claim back)."""
        saved = self._write(run, wizard_claim.same_claim(token), wizard_claim.released() if release else {})
        if saved is None:
            raise wizard_claim.lost(_(STEP_TITLES.get(step, step)))
        return saved

    def release(self, run_id: int, token: str) -> None:
        """Give the claim back without a result (the step ended unexpectedly: it reads interrupted)."""
        with transaction(self.url) as db:
            db.execute(update(LineWizardRow).where(LineWizardRow.id == run_id, wizard_claim.same_claim(token))
                       .values(**wizard_claim.released()))

    def _write(self, run: WizardRun, condition: ColumnElement[bool], extra: dict[str, None]) -> WizardRun | None:
        """One compare-and-set UPDATE of the body (None: the claim was not as expected, nothing written)."""
        with transaction(self.url) as db:
            written = wizard_claim.changed(db, update(LineWizardRow).where(LineWizardRow.id == run.id, condition)
                                           .values(body=_body(run), updated=datetime.now(UTC), **extra))
            if written != 1:
                return None
            row = db.get(LineWizardRow, run.id)
            assert row is not None
            return _of(row)


def refuse_while_running(run: WizardRun) -> None:
    """One change at a time: a step saves the whole run when it ends (the run as read, with its live claim)."""
    if run.claim is not None:
        raise wizard_claim.refusal(run.claim, _(STEP_TITLES.get(run.claim.step, run.claim.step)))
