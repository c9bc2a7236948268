"""Jobs between parameter sets and a device: upload a node into a set, download a set (preview, retry the
failed ones, roll back), and the device side of a comparison.

A download never stops silently halfway:

1. it reads the values of every parameter it will touch first and commits them (``parameter_download.before``)
   before the first write, so a rollback works even after a crash;
2. it writes only what differs, in a dependency-safe order (parameters that take effect after reset node last,
   communication ones - node address, baud rate, COB-IDs - at the very end), each verified by read-back;
3. every parameter ends in the report as ``written``, ``unchanged``, ``mismatch`` (the device holds another value),
   ``not verified`` (written, but it could not be read back), ``failed`` (with the abort code and text; the value
   the device now holds is read again) or ``not attempted`` (the node fell silent, or the job was cancelled) - and
   the report is stored whatever happens; the job and the stored download end ``done``, ``incomplete`` or
   ``failed`` by those lines (:mod:`~drivebench.services.sets.download_outcome`);
4. every write goes through :func:`writes.write`, so the audit log has a row for it.
"""

from __future__ import annotations

import asyncio
import uuid
from typing import Any

from pydantic import BaseModel

from drivebench import i18n
from drivebench.device.drive.motion import moves
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.profile import Profile
from drivebench.errors import (
    Conflict,
    DriveBenchError,
    SdoAbortError,
    SdoTimeoutError,
    UnknownParameter,
    WriteOutcomeUnknown,
)
from drivebench.i18n import N_, Text, _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.control import drive_guard
from drivebench.services.params import device_commands, read_all, reads, writes
from drivebench.services.params.jobs import Job, JobIssue, JobManager, said
from drivebench.services.params.write_context import WriteContext
from drivebench.services.sets.download_outcome import FAILED, NOT_WRITTEN, outcome_of
from drivebench.services.sets.parameter_sets import (
    ParameterSetStore,
    Raw,
    Source,
    StoredSet,
    Values,
    catalog_for,
    engineering,
    live_items,
    rpdo_mapped,
    same_raw,
    settable_items,
    shown,
)
from drivebench.services.storage.models import DownloadRow
from drivebench.services.storage.server_process import SERVER, ended
from drivebench.services.users import audit

SHOWN_WORDS = (N_("running"), N_("done"), N_("incomplete"), N_("cancelled"), N_("failed"), N_("interrupted"),
               N_("download"), N_("retry"), N_("rollback"), N_("will change"), N_("not attempted"), N_("unchanged"),
               N_("written"), N_("mismatch"), N_("not verified"), N_("sending"), N_("changed"), N_("only left"),
               N_("only right"), N_("unreadable"))
"""The states, kinds, report statuses, audit results and compare kinds of the sets page: English in the API, the
database and CSS classes; the page shows them through _()."""
REDO = ("failed", "mismatch", "not attempted", "not verified")
"""Report states a retry writes again."""
CHANGED = ("written", "not verified", "mismatch", "failed")
"""Report states a rollback restores (a failed write may still have changed the value)."""
WHAT_WRITES = {"download": N_("A download that writes {refs}"), "retry": N_("A retry that writes {refs}"),
               "rollback": N_("A rollback that writes {refs}")}
SAID = "detail_said"
"""A stored report line's detail as ``Text.saved`` keeps it (translated for each reader, see ``report_line``)."""


class ReportLine(BaseModel):
    """One parameter of a download report (also the API's answer)."""

    ref: str
    name: str
    status: str
    before: str | None
    target: str | None
    now: str | None
    """What the device holds after the download (read back, or read again after a failure)."""
    detail: str | None = None
    abort_code: str | None = None
    abort_text: str | None = None
    before_raw: Raw | None = None
    target_raw: Raw | None = None
    now_raw: Raw | None = None


def report_line(line: dict[str, Any]) -> ReportLine:
    """A report line as the job or the database holds it, its detail in the reader's language."""
    kept = line.get(SAID)
    return ReportLine(**{**line, "detail": i18n.shown(Text.loaded(kept))} if kept else line)


def _profile(node: SessionNode) -> Profile:
    if node.profile is None:
        raise Conflict(_("Node {node} has no device profile: assign one on the Plant page first").format(
            node=node.node_id))
    return node.profile


def _communication(item: Item) -> bool:
    group = (item.group or "").lower()
    return 0x1000 <= item.index <= 0x1FFF or "communication" in group or "can " in f"{group} "


def download_order(profile: Profile, refs: list[str]) -> list[str]:
    """Dependency-safe order: ordinary parameters (profile order), then those that need a reset node, then
    the communication parameters that need one (node address, baud rate, COB-IDs) - a drive that changes its
    address or bit rate must do so last."""
    catalog = catalog_for(profile)
    position = {item.ref: n for n, item in enumerate(catalog.items)}

    def key(ref: str) -> tuple[int, int]:
        item = position.get(ref)
        if item is None:
            return (0, len(position))
        found = catalog.items[item]
        rank = (2 if _communication(found) else 1) if found.entry.reset_required else 0
        return (rank, item)

    return sorted(refs, key=key)


# --- reading (the read-all machinery: SDO2 where there is one, silent nodes give up) ------------------------
async def read_items(session: Session, node: SessionNode, items: list[Item], job: Job, ctx: WriteContext
                     ) -> tuple[Values, dict[str, str]]:
    """Raw values by ref, and the refs that could not be read with why (what reading first writes, SDO2 switched
    on, is ``ctx``'s)."""
    first_issue = len(job.issues)
    job.result.setdefault("values", {}).pop(str(node.node_id), None)
    await read_all.read_node(session, node, items, job, ctx)
    found = job.result.get("values", {}).pop(str(node.node_id), {})
    values: Values = {}
    for ref, value in found.items():
        raw = value.raw
        values[ref] = raw.hex() if isinstance(raw, bytes) else raw
    unread = {i.item: (f"{i.abort_code} {i.abort_text}" if i.abort_code else i.detail)
              for i in job.issues[first_issue:]}
    return values, unread


async def device_source(session: Session, node_id: int, refs: list[str] | None = None, *,
                        ctx: WriteContext) -> Source:
    """The node's current values of its settable parameters (or of ``refs``), read now."""
    node = session.node(node_id)
    profile = _profile(node)
    catalog = catalog_for(profile)
    if refs is None:
        items = settable_items(profile)
    else:
        items = [item for ref in refs if (item := _resolve(catalog, ref)) is not None and item.entry.access.readable]
    job = Job(f"compare-{uuid.uuid4().hex[:6]}", "read", f"Read node {node_id}", len(items))
    values, unread = await read_items(session, node, items, job, ctx)
    unread = {ref: i18n.shown(why) for ref, why in unread.items()}  # this request's own comparison
    return Source(_("Node {node} ({device})").format(node=node_id, device=node.device_name), profile, values, unread)


def _resolve(catalog: Any, ref: str) -> Item | None:
    try:
        item: Item = catalog.resolve(ref)
    except UnknownParameter:
        return None
    return item


# --- upload ------------------------------------------------------------------------------------------------
def start_upload(session: Session, node_id: int, jobs: JobManager, store: ParameterSetStore, *, name: str,
                 ctx: WriteContext, note: str = "", user: str | None = None, into: int | None = None) -> Job:
    """A job reading every settable parameter of the node into a new set (``job.result['set_id']``), or into a
    new version of the set ``into`` (the older versions stay: history)."""
    node = session.node(node_id)
    profile = _profile(node)
    items = settable_items(profile)
    who = user or ctx.user
    if into is not None:
        _check_target(node, existing := store.get(into))
        name = existing.info.name

    remark = note or _("Uploaded from node {node} of session '{session}'").format(node=node_id,  # the set's note
                                                                                   session=session.name)

    async def run(job: Job) -> None:
        # what reading first writes (SDO2 switched on) is the upload's
        found, unread = await read_items(session, node, items, job, ctx.as_origin("upload", user=who))
        mapped = rpdo_mapped(found)
        values = {item.ref: found[item.ref] for item in items  # the profile's order
                  if item.ref in found and (item.index, item.subindex) not in mapped}
        left_out = [item.ref for item in live_items(profile)] + [item.ref for item in items
                                                                  if (item.index, item.subindex) in mapped]
        if left_out:
            job.notes.append(Text(N_("Left out as process data or volatile values (not settings): {refs}"),
                                  refs=", ".join(left_out)))
        if unread:
            job.notes.append(Text(N_("{count} parameters could not be read and are not in the set"),
                                   count=len(unread)))
        reason = f"upload from node {node_id}"
        if into is not None:
            stored = await asyncio.to_thread(store.update_values, into, values, user=who, reason=reason)
        else:
            stored = await asyncio.to_thread(store.create, name, profile, values, user=who, node_id=node_id,
                                             session_id=session.id, note=remark, reason=reason)
        job.result["set_id"] = stored.info.id
        job.result["version"] = stored.version

    return jobs.start("upload", Text(N_("Upload node {node} into '{name}'"), node=node_id, name=name), len(items),
                      run)


# --- preview -----------------------------------------------------------------------------------------------
async def preview(session: Session, node_id: int, stored: StoredSet, *, ctx: WriteContext) -> list[ReportLine]:
    """What a download would change: only the parameters whose device value differs from the set's."""
    node = session.node(node_id)
    profile = _check_target(node, stored)
    current = await device_source(session, node_id, list(stored.values), ctx=ctx)
    catalog = catalog_for(profile)
    lines: list[ReportLine] = []
    for ref in download_order(profile, list(stored.values)):
        target = stored.values[ref]
        before = current.values.get(ref)
        if before is not None and same_raw(before, target):
            continue
        item = _resolve(catalog, ref)
        if item is None:
            lines.append(ReportLine(ref=ref, name=_("(not in the profile)"), status="failed", before=None,
                                    target=str(target), now=None, detail=_("not a parameter of this profile"),
                                    target_raw=target))
            continue
        lines.append(ReportLine(ref=ref, name=item.name, status="will change", before=shown(item, before),
                                target=shown(item, target), now=shown(item, before), detail=current.unread.get(ref),
                                before_raw=before, target_raw=target, now_raw=before))
    return lines


def _check_target(node: SessionNode, stored: StoredSet) -> Profile:
    profile = _profile(node)
    if profile.id != stored.info.profile_id:
        raise Conflict(_("Set '{name}' is for {device} ({profile}); node {node} is a {node_device} ({node_profile})"
                         ).format(name=stored.info.name, device=stored.info.device, profile=stored.info.profile_id,
                                  node=node.node_id, node_device=node.device_name, node_profile=profile.id))
    return profile


# --- download, retry, rollback -----------------------------------------------------------------------------
async def held_moving(session: Session, node_id: int, targets: Values, *, ctx: WriteContext) -> Values:
    """What the node holds now of the ``targets`` that can move the drive (read now). A download, a retry and a
    rollback write only what differs, so each confirmation names only the moving values it changes: the route reads
    them with this and hands them to the job (``held=...``). ``targets``: :func:`download_targets`,
    :func:`retry_targets` or :func:`rollback_targets`."""
    profile = _profile(session.node(node_id))
    catalog = catalog_for(profile)
    refs = [ref for ref, raw in targets.items() if isinstance(raw, (int, float))
            and (item := _resolve(catalog, ref)) is not None and moves(item, raw, profile) is not None]
    return (await device_source(session, node_id, refs, ctx=ctx)).values if refs else {}


def download_targets(session: Session, node_id: int, stored: StoredSet, only: list[str] | None = None) -> Values:
    """What a download of ``stored`` (or of its refs ``only``) to the node writes where it differs."""
    _check_target(session.node(node_id), stored)
    return {ref: raw for ref, raw in stored.values.items() if only is None or ref in only}


def retry_targets(store: ParameterSetStore, download_id: int) -> Values:
    """What a retry of the download writes again: what it left failed, mismatched, unverified or not attempted."""
    previous = store.download(download_id)
    redo = {line["ref"]: line["target_raw"] for line in previous.report
            if line["status"] in REDO and line.get("target_raw") is not None}
    if not redo:
        raise Conflict(_("Download {id} has nothing left to retry").format(id=download_id))
    return redo


def rollback_targets(store: ParameterSetStore, download_id: int) -> Values:
    """What a rollback of the download writes: the values read first, of everything it changed (or may have)."""
    previous = store.download(download_id)
    if previous.report:
        touched = [line["ref"] for line in previous.report if line["status"] in CHANGED]
    else:  # interrupted before its report was stored: restore everything it read first
        touched = list(previous.before)
    targets = {ref: previous.before[ref] for ref in touched if ref in previous.before}
    if not targets:
        raise Conflict(_("Download {id} changed nothing that could be rolled back").format(id=download_id))
    return targets


def start_download(session: Session, node_id: int, jobs: JobManager, store: ParameterSetStore, stored: StoredSet,
                   *, ctx: WriteContext, save: bool = False, only: list[str] | None = None, user: str | None = None,
                   confirm: object = None, held: Values | None = None) -> Job:
    """Download the set (or only the refs ``only``: a retry of the failed ones) to the node. A set with values
    that can move the drive needs ``confirm`` naming the node (or the request's confirmation) and the moving values
    it will write: with ``held`` (:func:`held_moving`) only those that differ from what the node holds. A value
    that changed on the node meanwhile is not confirmed: its write is refused and reported as failed."""
    node = session.node(node_id)
    targets = download_targets(session, node_id, stored, only)
    kind = "download" if only is None else "retry"
    title = Text(N_("Download '{name}' to node {node}") if only is None else N_("Retry '{name}' to node {node}"),
                  name=stored.info.name, node=node_id)
    return _start(session, node, jobs, store, targets, ctx, kind=kind, title=title, save=save, user=user,
                  set_id=stored.info.id, set_version=stored.version, confirm=confirm, held=held)


def start_retry(session: Session, jobs: JobManager, store: ParameterSetStore, download_id: int,
                *, ctx: WriteContext, save: bool = False, user: str | None = None, confirm: object = None,
                held: Values | None = None) -> Job:
    """Write again what a download left failed, mismatched, unverified or not attempted; with ``held``
    (:func:`held_moving` of :func:`retry_targets`) it confirms only the moving values it changes, as a download
    does."""
    previous = store.download(download_id)
    redo = retry_targets(store, download_id)
    node = session.node(previous.node_id)
    return _start(session, node, jobs, store, redo, ctx, kind="retry", save=save, user=user,
                  title=Text(N_("Retry {count} parameters of download {id} on node {node}"), count=len(redo),
                              id=download_id, node=node.node_id),
                  set_id=previous.set_id, set_version=previous.set_version, confirm=confirm, held=held)


def start_rollback(session: Session, jobs: JobManager, store: ParameterSetStore, download_id: int,
                   *, ctx: WriteContext, save: bool = False, user: str | None = None, confirm: object = None,
                   held: Values | None = None) -> Job:
    """Write back the values a download read first, for everything it changed (or may have changed); with ``held``
    (:func:`held_moving` of :func:`rollback_targets`) it confirms only the moving values it changes."""
    previous = store.download(download_id)
    node = session.node(previous.node_id)
    targets = rollback_targets(store, download_id)
    return _start(session, node, jobs, store, targets, ctx, kind="rollback", save=save, user=user,
                  title=Text(N_("Roll back download {id} on node {node}"), id=download_id, node=node.node_id),
                  set_id=previous.set_id,
                  set_version=previous.set_version, confirm=confirm, held=held)


def _moving(profile: Profile, items: dict[str, Item], order: list[str], targets: Values, held: Values | None
            ) -> tuple[list[str], dict[str, Any]]:
    """The refs of ``targets`` that can move the drive and differ from what the node holds (``held``), and the
    values their confirmation names."""
    moving = [ref for ref in order if ref in items and isinstance(targets[ref], (int, float))
              and moves(items[ref], targets[ref], profile) is not None
              and not (held is not None and ref in held and same_raw(held[ref], targets[ref]))]
    values = {key: value for ref in moving
              for key, value in writes.sent_value(items[ref], engineering(items[ref], targets[ref])).items()}
    return moving, values


async def download_moving_values(session: Session, node_id: int, stored: StoredSet, *, ctx: WriteContext
                                 ) -> tuple[Values, dict[str, Any]]:
    """(``held``, the values a download of ``stored`` to the node would ask to confirm; empty: nothing that can move
    the drive), read now as the download route reads them: a caller that confirms several downloads at once names
    these and starts each with its ``held``."""
    targets = download_targets(session, node_id, stored)
    held = await held_moving(session, node_id, targets, ctx=ctx)
    profile = _profile(session.node(node_id))
    catalog = catalog_for(profile)
    order = download_order(profile, list(targets))
    items = {ref: item for ref in order if (item := _resolve(catalog, ref)) is not None}
    return held, _moving(profile, items, order, targets, held)[1]


def _start(session: Session, node: SessionNode, jobs: JobManager, store: ParameterSetStore, targets: Values,
           ctx: WriteContext, *,
           kind: str, title: str, save: bool, user: str | None, set_id: int | None,
           set_version: int | None, confirm: object = None, held: Values | None = None) -> Job:
    profile = _profile(node)
    order = download_order(profile, list(targets))
    catalog = catalog_for(profile)
    items = {ref: item for ref in order if (item := _resolve(catalog, ref)) is not None}
    readable = [items[ref] for ref in order if ref in items and items[ref].entry.access.readable]
    who = user or ctx.user
    ctx = ctx.confirming(confirm)  # the job's own writes carry it
    moving, values = _moving(profile, items, order, targets, held)
    if moving:  # asked before anything is read or written; each such write arms the guard as it goes out
        refs = ", ".join(moving[:4]) + (" ..." if len(moving) > 4 else "")
        ctx = drive_guard.confirm_moving(session, node.node_id, _(WHAT_WRITES[kind]).format(refs=refs), values,
                                         ctx)[1]

    async def run(job: Job) -> None:
        # what reading first writes (SDO2 switched on) is the download's, before its id
        before, unread = await read_items(session, node, readable, job, ctx.as_origin(kind, user=who))
        download_id = await asyncio.to_thread(
            store.start_download, kind=kind, session_id=session.id, node_id=node.node_id, profile_id=profile.id,
            user=who, before=before, set_id=set_id, set_version=set_version)
        job.result["download_id"] = download_id
        writer = _Writer(session, node, job, items, before, unread, ctx.as_origin(f"{kind} {download_id}", user=who))
        state = "failed"
        try:
            await writer.write_all(order, targets)
            await writer.read_failed_again()
            if save:
                await writer.save()
            outcome = outcome_of(writer.report())
            state = outcome.state.value
            job.result["outcome"] = outcome.model_dump()
            job.conclude(outcome.state, outcome.why_failed())
        except asyncio.CancelledError:
            writer.give_up(Text(N_("cancelled before this parameter was written")))
            state = "cancelled"
            raise
        finally:
            job.result["state"] = state
            await asyncio.shield(asyncio.to_thread(store.finish_download, download_id, state, writer.report()))

    total = len(readable) + len(order) + (1 if save else 0)
    return jobs.start(kind, title, total, run)


class _Writer:
    def __init__(self, session: Session, node: SessionNode, job: Job, items: dict[str, Item], before: Values,
                 unread: dict[str, str], ctx: WriteContext) -> None:
        self.session, self.node, self.job, self.ctx = session, node, job, ctx
        self.items, self.before, self.unread = items, before, unread
        self.lines: dict[str, ReportLine] = {}
        self.said: dict[str, Text] = {}
        """The details that are a ``Text``, by ref (a ReportLine keeps only the English text)."""
        self.silence = read_all.silence_watch(session, node.node_id)
        """Gives the node up only on evidence (:mod:`~drivebench.services.params.node_silence`), not after two slow
        answers on a busy machine."""

    def report(self) -> list[dict[str, Any]]:
        return [line.model_dump() | ({SAID: kept.saved()} if (kept := self.said.get(line.ref)) is not None
                                     and kept == line.detail else {}) for line in self.lines.values()]

    def _say(self, line: ReportLine, detail: str | None) -> str | None:
        line.detail = detail
        if isinstance(detail, Text):
            self.said[line.ref] = detail
        return detail

    def failures(self) -> list[ReportLine]:
        """Lines whose value did not go in (failed, mismatched, not written)."""
        return [line for line in self.lines.values() if line.status in FAILED + NOT_WRITTEN]

    def _publish(self) -> None:
        self.job.result["report"] = self.report()

    def _line(self, ref: str, target: Raw) -> ReportLine:
        item = self.items.get(ref)
        before = self.before.get(ref)
        name = item.name if item else "(not in the profile)"
        line = ReportLine(ref=ref, name=name, status="not attempted", before=shown(item, before) if item else None,
                          target=shown(item, target) if item else str(target),
                          now=shown(item, before) if item else None, before_raw=before, target_raw=target,
                          now_raw=before)
        self.lines[ref] = line
        return line

    async def write_all(self, order: list[str], targets: Values) -> None:
        for ref in order:
            self._line(ref, targets[ref])
        for ref in order:
            await self._write_one(self.lines[ref])
            self._publish()

    async def _write_one(self, line: ReportLine) -> None:
        item = self.items.get(line.ref)
        target = line.target_raw
        assert target is not None
        if item is None:
            line.status = "failed"
            detail = self._say(line, Text(N_("not a parameter of this device's profile (not sent)")))
            self.job.advance(issue=JobIssue(line.ref, detail or "", self.node.node_id))
            return
        if self.silence.verdict is not None:  # not written: given up, as a read-all gives up a silent node
            self._say(line, Text(N_("node {node} stopped answering; not sent (value as read before)"),
                                 node=self.node.node_id))
            self.job.give_up(1)
            return
        if line.before_raw is not None and same_raw(line.before_raw, target):
            line.status = "unchanged"
            self.job.advance()
            return
        try:
            result = await writes.write(self.session, self.node.node_id, item.ref, engineering(item, target),
                                            ctx=self.ctx)
        except SdoTimeoutError as exc:
            await self.silence.timed_out(exc)
            line.status = "failed"
            line.now = exc.read_back if isinstance(exc, WriteOutcomeUnknown) else None  # its read-back said
            line.now_raw = None
            self.job.advance(issue=JobIssue(line.ref, self._say(line, said(exc)) or "", self.node.node_id))
            return
        except SdoAbortError as exc:
            self.silence.answered()
            line.status = "failed"
            line.abort_code, line.abort_text = f"0x{exc.abort_code:08X}", exc.abort_text
            self.job.advance(issue=JobIssue(line.ref, self._say(line, said(exc)) or "", self.node.node_id,
                                            line.abort_code, exc.abort_text))
            return
        except DriveBenchError as exc:  # refused by the profile's checks before anything was sent
            line.status = "failed"
            detail = self._say(line, Text(N_("not sent: {why}"), why=said(exc)))
            self.job.advance(issue=JobIssue(line.ref, detail or "", self.node.node_id))
            return
        self.silence.answered()
        state, detail = audit.outcome(result, None)
        line.status = state  # written (and read back), not verified, or mismatch
        self._say(line, detail)
        if result.read_back is not None:
            raw = result.read_back.raw
            line.now_raw = raw.hex() if isinstance(raw, bytes) else raw
            line.now = result.read_back.display
        else:
            line.now_raw, line.now = target, line.target
        if line.status == "mismatch":
            self.job.advance(issue=JobIssue(line.ref, detail or Text(N_("mismatch")), self.node.node_id))
        else:
            self.job.advance()

    async def read_failed_again(self) -> None:
        """After an abort the device holds *some* value: read it, so the report says which."""
        if self.silence.verdict is not None:
            return
        for line in self.lines.values():
            item = self.items.get(line.ref)
            if line.status != "failed" or item is None or line.abort_code is None:
                continue
            try:
                value = await reads.read(self.session, self.node.node_id, item.ref)
            except DriveBenchError:
                continue
            line.now_raw = value.raw.hex() if isinstance(value.raw, bytes) else value.raw
            line.now = value.display
        self._publish()

    async def save(self) -> None:
        failed = self.failures()
        if failed:
            self.job.notes.append(Text(N_("Not saved on the device: {count} parameters did not get their value"),
                                        count=len(failed)))
            self.job.advance()
            return
        try:
            done = await device_commands.command(self.session, self.node.node_id, device_commands.DeviceCommand.SAVE,
                                            ctx=self.ctx)
        except DriveBenchError as exc:
            self.job.advance(issue=JobIssue("save", said(exc), self.node.node_id))
            self.job.notes.append(Text(N_("Save failed: {why}"), why=said(exc)))
            return
        self.job.notes.append(Text(N_("Saved on the device ({via})"), via=done.via))
        self.job.result["saved"] = done.via
        self.job.advance()

    def give_up(self, why: str) -> None:
        for line in self.lines.values():
            if line.status == "not attempted" and line.detail is None:
                self._say(line, why)


def running_downloads(jobs: JobManager) -> set[int]:
    """Ids of the downloads whose job is still running in this process."""
    return {int(job.result["download_id"]) for job in jobs.list()
            if not job.state.finished and "download_id" in job.result}


def download_state(row: DownloadRow, jobs: JobManager) -> str:
    """The stored state, except that a row still ``running`` whose server no longer runs it was interrupted.

    This process knows its own jobs. Another server of the database (``row.server``: host and process id) is judged
    gone only on this machine, where its process can be looked up; another machine's download stays ``running``
    until that server ends it."""
    if row.state != "running":
        return row.state
    if row.server in (None, SERVER):
        return "running" if row.id in running_downloads(jobs) else "interrupted"
    return "interrupted" if ended(row.server) else "running"


def close_interrupted(store: ParameterSetStore) -> list[int]:
    """At start-up: downloads left ``running`` by an ended server process of this machine (killed, crashed) are
    stored as interrupted, so every server of the database says so (ids returned)."""
    return store.interrupt_downloads(lambda server: server != SERVER and ended(server))


