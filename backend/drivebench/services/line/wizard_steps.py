"""The steps of the "New line" wizard, each calling the service that does it alone: LSS fastscan and addressing
(``services/lss``), the boot-up check (``boot_check``), the verified parameter-set download (``services/sets``) and
the program download (``services/program``). Their safety rules stay: a step that reaches every device on the bus
asks one confirmation naming ``all`` and every value it will send (428), and is refused while a node is enabled or
armed (409); the set and program downloads are asked for, node by node, in one confirmation naming ``all``. Each
step writes its result in words to the run (:mod:`wizard_run`); a step can be run again alone."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from drivebench.errors import ConfirmationRequired, Conflict, DriveBenchError, InvalidValue, NotFound
from drivebench.i18n import _
from drivebench.protocol.canopen.lss import LssAddress
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_guard import require_confirmation
from drivebench.services.line.boot_check import boot_check
from drivebench.services.line.project import LineProject, ProjectNode
from drivebench.services.line.wizard_claim import keep
from drivebench.services.line.wizard_run import FoundDevice, WizardRun, WizardStore
from drivebench.services.lss import line as lss
from drivebench.services.lss.guard_rule import EVERY_DEVICE, admit_global
from drivebench.services.lss.identify import identify
from drivebench.services.params.jobs import JobManager, JobState
from drivebench.services.params.write_context import Confirmation, WriteContext
from drivebench.services.program import download as program
from drivebench.services.program.program_info import program_info
from drivebench.services.sets import set_jobs
from drivebench.services.sets.parameter_sets import ParameterSetStore

NOTHING_DONE = (InvalidValue, Conflict, NotFound)
"""Refusals raised before a step sends anything: the step keeps its state and the request answers the problem (as
for a confirmation asked for: every step asks before it sends)."""


@dataclass
class StepCall:
    run: WizardRun
    session: Session
    project: LineProject
    ctx: WriteContext
    jobs: JobManager
    window_ms: float = 50
    lines: list[str] | None = None

    def say(self, text: str) -> None:
        assert self.lines is not None
        self.lines.append(text)


def _label(node: ProjectNode) -> str:
    return _("node {node} ({name})").format(node=node.node_id, name=node.name or node.device)


# --- 1 scan --------------------------------------------------------------------------------------------------------
def _proposals(project: LineProject, found: list[FoundDevice]) -> dict[int, str]:
    """Planned node -> serial: where the project names the serial; else where exactly one found device and one
    planned node share vendor and product."""
    proposed: dict[int, str] = {}
    for node in project.nodes:
        wanted = node.identity.serial
        match = next((device for device in found if wanted is not None and int(device.serial, 16) == wanted), None)
        if match is not None:
            proposed[node.node_id] = match.serial
    taken = set(proposed.values())
    for node in project.nodes:
        if node.node_id in proposed or node.identity.vendor_id is None or node.identity.product_code is None:
            continue
        same = [device for device in found if device.serial not in taken
                and int(device.vendor, 16) == node.identity.vendor_id
                and int(device.product, 16) == node.identity.product_code]
        siblings = [other for other in project.nodes if other.node_id not in proposed
                    and other.identity.vendor_id == node.identity.vendor_id
                    and other.identity.product_code == node.identity.product_code]
        if len(same) == 1 and len(siblings) == 1:
            proposed[node.node_id] = same[0].serial
            taken.add(same[0].serial)
    return proposed


async def scan(call: StepCall) -> bool:
    result = await lss.fastscan(call.session, call.ctx, call.window_ms)
    run = call.run
    run.found = []
    told: list[str] = []
    profiles = call.session.profiles.all()
    for address in result.found:
        known = identify(profiles, address)  # the LSS page's words: a vendor's device without a product code is named
        run.found.append(FoundDevice(**address.hex(), device=known.device or known.vendor_name))
        told.append(known.text)
    call.say(_("{count} devices without node ID found ({frames} frames, {seconds} s).").format(
        count=len(run.found), frames=result.frames, seconds=f"{result.seconds:.2f}"))
    for device, text in zip(run.found, told, strict=True):
        call.say(_("serial {serial}: vendor {vendor}, product {product}, revision {revision} ({device}).").format(
            **device.model_dump(exclude={"device"}), device=text))
    run.proposed = _proposals(call.project, run.found)
    serials = {device.serial for device in run.found}
    kept = {node: serial for node, serial in run.assignments.items() if serial in serials}
    run.assignments = {**run.proposed, **kept}
    for node_id, serial in sorted(run.proposed.items()):
        call.say(_("proposed: serial {serial} for {node}.").format(serial=serial,
                                                                    node=_label(call.project.node(node_id))))
    return True


# --- 2 assign, 3 store --------------------------------------------------------------------------------------------
def _bitrate(node: ProjectNode) -> int:
    return node.baud_kbit * 1000


def _assignments(call: StepCall) -> list[tuple[ProjectNode, FoundDevice]]:
    found = {device.serial: device for device in call.run.found}
    pairs = []
    for node_id, serial in sorted(call.run.assignments.items()):
        if serial in found:
            pairs.append((call.project.node(node_id), found[serial]))
    if not pairs:
        raise InvalidValue(_("No found device is given a planned node: run the scan, then drag a serial onto a "
                             "planned node (or choose it in the node's list)."))
    return pairs


def assign_values(pairs: list[tuple[ProjectNode, FoundDevice]]) -> dict[str, object]:
    return {"LSS": "assign", "nodes": [f"serial {device.serial} -> node {node.node_id}, {_bitrate(node)} bit/s"
                                       for node, device in pairs],
            "store": False, "then": lss.SWITCH_GLOBAL_WAITING, "if it had a node ID": lss.RESET_OLD_ID}


def _each(values: dict[str, object]) -> Confirmation:
    """The confirmation of one device's LSS step, part of the step's confirmed whole."""
    return Confirmation("all", {"reaches": EVERY_DEVICE, **values})


async def assign(call: StepCall) -> bool:
    pairs = _assignments(call)
    await admit_global(call.session, _("The wizard's LSS addressing"), assign_values(pairs), call.ctx)
    ok = True
    for node, device in pairs:
        address = device.address()
        bitrate = _bitrate(node)
        each = call.ctx.confirming(_each(lss.assign_values(address, node.node_id, bitrate, False)))
        try:
            steps = await lss.assign(call.session, each, address, node.node_id, bitrate=bitrate, store=False)
        except lss.LssStepFailed as exc:
            ok = False
            call.say(_("{node}: serial {serial} not addressed: {why}").format(node=_label(node), serial=device.serial,
                                                                             why=exc.detail))
            continue
        booted = all(step.ok for step in steps)
        ok = ok and booted
        call.run.assigned[node.node_id] = device
        call.say(_("{node}: serial {serial}: {steps}").format(node=_label(node), serial=device.serial,
                                                             steps="; ".join(step.text for step in steps)))
        if booted:
            _adopt_profile(call, node)
    return ok


def _adopt_profile(call: StepCall, node: ProjectNode) -> None:
    """The node joins the session with the project's profile and name where the device's identity (0x1018 vendor
    and product) agrees with that profile: two devices of one vendor and product code (8400 motec and 8200 vector
    both report Lenze, product 0) cannot pick their profile from the identity alone, the project says it."""
    joined = call.session.nodes.get(node.node_id)
    if joined is None or node.profile is None:
        return
    try:
        profile = call.session.profiles.get(node.profile.id)
    except DriveBenchError:
        return
    stated = {"vendor_id": profile.identity.vendor_id, "product_code": profile.identity.product_code}
    if any(key in joined.identity and value is not None and joined.identity[key] != value
           for key, value in stated.items()):
        call.say(_("{node}: the device's identity does not match the project's profile '{profile}': it keeps the "
                   "profile its identity picked.").format(node=_label(node), profile=profile.id))
        return
    joined.name = joined.name or node.name or None
    if joined.profile is None or joined.profile.id != profile.id:
        joined.profile = profile
        call.say(_("{node}: handled with the project's profile '{profile}'.").format(node=_label(node),
                                                                                   profile=profile.id))


def store_values(pairs: list[tuple[int, FoundDevice]]) -> dict[str, object]:
    return {"LSS": "store configuration",
            "devices": [f"serial {device.serial} (node {node_id})" for node_id, device in pairs],
            "then": lss.SWITCH_GLOBAL_WAITING}


async def store(call: StepCall) -> bool:
    pairs = sorted(call.run.assigned.items())
    if not pairs:
        raise InvalidValue(_("No device has been addressed yet: run step 2 (assign node IDs) first."))
    await admit_global(call.session, _("The wizard's LSS store configuration"), store_values(pairs), call.ctx)
    ok = True
    for node_id, device in pairs:
        address: LssAddress = device.address()
        each = call.ctx.confirming(_each(lss.store_values(address)))
        try:
            steps = await lss.store_configuration(call.session, each, address)
        except lss.LssStepFailed as exc:
            ok = False
            call.say(_("node {node}: serial {serial}: the configuration was not stored: {why}").format(
                node=node_id, serial=device.serial, why=exc.detail))
            continue
        call.say(_("node {node}: serial {serial}: {steps}").format(node=node_id, serial=device.serial,
                                                                  steps="; ".join(step.text for step in steps)))
    return ok


# --- 4 boot-up check ----------------------------------------------------------------------------------------------
async def check(call: StepCall) -> bool:
    result = await boot_check(call.project, call.session)
    for node in result.nodes:
        for message in node.messages:
            call.say(message)
    call.say(_("The line matches its project.") if result.ok else _("The line differs from its project."))
    return result.ok


# --- 5 parameter sets ---------------------------------------------------------------------------------------------
async def sets(call: StepCall) -> bool:
    store_ = ParameterSetStore()
    planned: list[tuple[ProjectNode, Any, Any, dict[str, Any]]] = []
    ok = True
    for node in call.project.nodes:
        chosen = node.parameter_set
        if chosen is None or chosen.set_id is None:
            call.say(_("{node}: the project holds no parameter set for it.").format(node=_label(node)))
            continue
        if node.node_id not in call.session.nodes:
            ok = False
            call.say(_("{node}: not in the session, its set '{name}' was not downloaded (run the boot-up check)."
                       ).format(node=_label(node), name=chosen.name))
            continue
        stored = await asyncio.to_thread(store_.get, chosen.set_id)  # a database read: not on the event loop
        held, values = await set_jobs.download_moving_values(call.session, node.node_id, stored, ctx=call.ctx)
        planned.append((node, stored, held, values))
    asked = {f"node {node.node_id}: {key}": value for node, _stored, _held, values in planned
             for key, value in values.items()}
    if asked:
        require_confirmation(call.ctx.confirmation, None, _("The wizard's parameter-set downloads"), asked)
    for node, stored, held, values in planned:
        job = set_jobs.start_download(call.session, node.node_id, call.jobs, store_, stored, ctx=call.ctx,
                                      user=call.ctx.user, held=held,
                                      confirm=Confirmation(node.node_id, values) if values else None)
        await job.wait()
        outcome = job.result.get("outcome") or {}
        counts = {key: outcome.get(key, 0) for key in ("written", "verified", "failed", "not_written")}
        if job.state is JobState.DONE:
            call.say(_("{node}: parameter set '{name}' downloaded, every value written and read back ({written}; "
                       "download {id}).").format(node=_label(node), name=stored.info.name,
                                                  id=job.result.get("download_id"), **counts))
        else:
            ok = False
            call.say(_("{node}: parameter set '{name}' {state}: {written} written, {verified} read back, {failed} "
                       "failed, {not_written} not written (download {id}: retry it on the Parameter sets page). "
                       "{why}").format(node=_label(node), name=stored.info.name, state=job.state.value,
                                       id=job.result.get("download_id"), why=job.error or "", **counts).strip())
    return ok


# --- 6 program download -------------------------------------------------------------------------------------------
def _same_version(found: str | None, expected: str) -> bool:
    if found is None:
        return False
    with contextlib.suppress(ValueError):
        return int(found, 0) == int(expected, 0)
    return found.strip().lower() == expected.strip().lower()


async def firmware(call: StepCall) -> bool:
    asked_for = [node for node in call.project.nodes if node.firmware_version]
    if not asked_for:
        call.say(_("The project asks for no program download."))
        return True
    ok = True
    pending: list[tuple[ProjectNode, str, Any]] = []
    for node in asked_for:
        expected = str(node.firmware_version)
        if node.node_id not in call.session.nodes:
            ok = False
            call.say(_("{node}: not in the session, its firmware cannot be checked.").format(node=_label(node)))
            continue
        try:
            now = (await program_info(call.session, node.node_id)).software_id
        except DriveBenchError as exc:
            now = None
            call.say(_("{node}: its software identification (0x1F56) could not be read: {why}").format(
                node=_label(node), why=exc.detail))
        if _same_version(now, expected):
            call.say(_("{node} runs firmware {version} already, as the project expects: nothing sent.").format(
                node=_label(node), version=now))
            continue
        chosen = call.run.firmware.get(node.node_id)
        if chosen is None:
            ok = False
            call.say(_("{node} reports firmware {found}, the project expects {expected}: choose the firmware file "
                       "for it and run this step again.").format(node=_label(node), found=now or "-",
                                                                 expected=expected))
            continue
        try:
            checked = await program.checked_file(call.session, node.node_id, chosen.file_id)
        except NotFound:
            ok = False
            call.say(_("{node}: the firmware file {file} is no longer kept by the server (a newer file was checked "
                       "for this node since): choose it again.").format(node=_label(node), file=chosen.name))
            continue
        pending.append((node, expected, checked))
    asked = {f"node {node.node_id}: {key}": value for node, _expected, checked in pending
             for key, value in program.download_values(checked).items()}
    if asked:
        require_confirmation(call.ctx.confirmation, None, _("The wizard's program downloads"), asked)
    for node, expected, checked in pending:
        each = call.ctx.confirming(Confirmation(node.node_id, program.download_values(checked)))
        job = program.start_download(call.session, node.node_id, call.jobs, checked, each)
        await job.wait()
        found = job.result.get("software_id")
        if job.state is not JobState.DONE:
            ok = False
            call.say(_("{node}: program download of {file} failed: {why}").format(
                node=_label(node), file=checked.name, why=job.error or job.state.value))
        elif not _same_version(found, expected):
            ok = False
            call.say(_("{node}: {file} was downloaded and started, but the device reports firmware {found}, the "
                       "project expects {expected}.").format(node=_label(node), file=checked.name, found=found,
                                                             expected=expected))
        else:
            call.say(_("{node}: {file} downloaded and started; the device reports firmware {found}, as the project "
                       "expects.").format(node=_label(node), file=checked.name, found=found))
    return ok


STEP_FUNCTIONS: dict[str, Callable[[StepCall], Awaitable[bool]]] = {
    "scan": scan, "assign": assign, "store": store, "boot_check": check, "sets": sets, "program": firmware}


async def run_step(call: StepCall, name: str, store_: WizardStore) -> WizardRun:
    """Run one step and keep its result. A refusal before anything was sent (428, 409, 422, 404) leaves the step as
    it was and is raised; a failure on the way is the step's result in words. The step is claimed in the database
    first (409 while any step of the run runs on any server) and its lease renewed while it runs."""
    run = call.run
    if name not in STEP_FUNCTIONS:
        raise NotFound(_("The wizard has no step '{step}'.").format(step=name))
    token = await asyncio.to_thread(store_.claim, run.id, name)
    renewing = asyncio.create_task(keep(store_, run.id, token))
    released = False
    try:
        run = await asyncio.to_thread(store_.get, run.id)  # as it is now, not as the request found it
        before = run.step(name).model_copy(deep=True)
        step = run.step(name)
        step.state, step.lines, step.runs = "running", [], step.runs + 1
        call.run = run = await asyncio.to_thread(store_.save_claimed, run, name, token)
        call.lines = run.step(name).lines
        try:
            ok = await STEP_FUNCTIONS[name](call)
        except DriveBenchError as exc:
            if isinstance(exc, ConfirmationRequired) or (not call.lines and isinstance(exc, NOTHING_DONE)):
                run.steps[name] = before
                released = True
                await asyncio.to_thread(store_.save_claimed, run, name, token, release=True)
                raise
            call.say(str(exc.detail))
            ok = False
        done = run.step(name)
        done.state, done.finished = ("done" if ok else "failed"), datetime.now(UTC)
        released = True
        return await asyncio.to_thread(store_.save_claimed, run, name, token, release=True)
    finally:
        renewing.cancel()
        if not released:  # ended on the way (cancelled, a fault): no claim left behind, the step reads interrupted
            with contextlib.suppress(Exception):
                await asyncio.to_thread(store_.release, run.id, token)
