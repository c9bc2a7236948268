"""Read-all: every readable parameter (or one group) of the nodes as a job. One node's reads are spread over its
SDO channels (:mod:`drivebench.services.params.sdo2`) and different nodes run in parallel; a read that timed out is
asked again at the end, a node judged silent from evidence (:mod:`drivebench.services.params.node_silence`) is
given up and never holds the others up."""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Iterable
from functools import partial

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.errors import (
    InvalidValue,
    ProtocolError,
    SdoAbortError,
    SdoOutOfStepError,
    SdoTimeoutError,
    TransportError,
    UnknownParameter,
)
from drivebench.i18n import N_, Text, _
from drivebench.protocol.datatypes import DataType
from drivebench.services.bus.fieldbus import SdoClient
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params.jobs import Job, JobIssue, JobManager, said
from drivebench.services.params.lookup import readable_items
from drivebench.services.params.node_silence import NodeSilence
from drivebench.services.params.reads import Plan, plan_of, upload
from drivebench.services.params.sdo2 import sdo_channels
from drivebench.services.params.session_part import service
from drivebench.services.params.write_context import READ_ALL_ORIGIN, WriteContext


def _issue(node_id: int, item: Item, exc: Exception) -> JobIssue:
    detail = said(exc)
    if isinstance(exc, SdoAbortError):
        return JobIssue(item.ref, detail, node_id, f"0x{exc.abort_code:08X}", exc.abort_text)
    return JobIssue(item.ref, detail, node_id)


_DEVICE_TYPE = Plan(Item("0x1000", 0x1000, 0, ObjectEntry(name="Device type", data_type=DataType.UNSIGNED32,
                                                            access=Access.RO, index=0x1000, subindex=0)))
"""What a silence probe reads: CiA 301 0x1000, mandatory on every device."""


def _silence(session: Session, client: SdoClient, channel: int) -> NodeSilence:
    return NodeSilence(client.node_id, partial(upload, client, _DEVICE_TYPE, channel=channel), session.heartbeat)


def silence_watch(session: Session, node_id: int) -> NodeSilence:
    """Evidence whether the node has gone silent, for a long job that writes or reads it on its first channel."""
    return _silence(session, session.client(node_id), 1)


async def read_node(session: Session, node: SessionNode, work: list[Item], job: Job, ctx: WriteContext) -> None:
    """Read the items over the node's SDO channels (``ctx``: whose writes switch its SDO2 on). A read that times out
    is asked again at the end; the node is given up only when :class:`NodeSilence` judges it silent (not after two
    slow answers)."""
    state = service(session)
    client = session.client(node.node_id)
    key = str(node.node_id)
    values: dict[str, object] = job.result.setdefault("values", {}).setdefault(key, {})
    channel_numbers = await sdo_channels(session, node, ctx)
    note = state.channels.get(node.node_id)
    if note is not None and note.note and note.note not in job.notes:
        job.notes.append(note.note)
    silence = _silence(session, client, channel_numbers[0])
    timed_out: dict[str, tuple[Item, Exception]] = {}

    def failed(item: Item, exc: Exception) -> None:
        issue = _issue(node.node_id, item, exc)
        state.not_read(node.node_id, item.ref, issue.detail)
        job.advance(issue=issue)

    retried: list[str] = []
    failed_again: list[str] = []

    async def drain(queue: deque[Item], channel: int, last_pass: bool) -> None:
        while queue and silence.verdict is None:
            item = queue.popleft()
            try:
                plan = plan_of(node.catalog, item)
                data = await upload(client, plan, channel=channel)
                value = plan.value(plan.decode(data, node.node_id))
            except (SdoTimeoutError, SdoOutOfStepError) as exc:
                if last_pass:
                    failed_again.append(item.ref)
                    failed(item, exc)
                else:
                    timed_out[item.ref] = (item, exc)  # counted when asked again (or given up)
                await silence.timed_out(exc)
                continue
            except (ProtocolError, InvalidValue) as exc:
                failed(item, exc)
                continue
            silence.answered()
            state.remember(node.node_id, value)
            values[item.ref] = value
            job.advance()

    queue = deque(work)
    await asyncio.gather(*(drain(queue, channel, False) for channel in channel_numbers))
    if timed_out and silence.verdict is None:
        again = deque(item for item, _error in timed_out.values())
        retried.extend(item.ref for item in again)
        timed_out.clear()
        await asyncio.gather(*(drain(again, channel, True) for channel in channel_numbers))
        queue.extend(again)  # left over if the node fell silent meanwhile
    if retried:
        job.result.setdefault("retried", {})[key] = retried
        job.result.setdefault("failed_after_retry", {})[key] = failed_again
        job.notes.append(Text(N_("Node {node}: {count} parameters timed out and were asked again at the end, "
                                  "{answered} of them answered"), node=node.node_id, count=len(retried),
                               answered=len(retried) - len(failed_again)))
    if silence.verdict is not None:
        for item, exc in timed_out.values():
            failed(item, exc)
        given_up = Text(N_("Node {node} {verdict}; {count} parameters not read"), node=node.node_id,
                        verdict=Text(silence.verdict), count=len(queue))
        job.notes.append(given_up)
        for item in queue:
            state.not_read(node.node_id, item.ref, given_up)
        job.give_up(len(queue))


def start_read(session: Session, node_ids: Iterable[int], jobs: JobManager, *, ctx: WriteContext,
               group: str | None = None, parameter_set: int = 1) -> Job:
    """A job reading every readable parameter (or one group) of the nodes, the codes kept per parameter set in
    ``parameter_set``; different nodes in parallel. What it writes (a node's SDO2 switched on) is ``ctx``'s, with
    the origin ``read-all``."""
    ctx = ctx.as_origin(READ_ALL_ORIGIN)
    nodes = [session.node(node_id) for node_id in node_ids]
    work = {node.node_id: readable_items(node, group, parameter_set) for node in nodes}
    if group is not None and not any(work.values()):
        raise UnknownParameter(_("No readable parameters in group '{group}'").format(group=group))
    total = sum(len(found) for found in work.values())
    if len(nodes) == 1:
        title = (Text(N_("Read group '{group}' of node {node}"), group=group, node=nodes[0].node_id) if group
                 else Text(N_("Read all parameters of node {node}"), node=nodes[0].node_id))
    else:
        title = (Text(N_("Read group '{group}' of {count} nodes"), group=group, count=len(nodes)) if group
                 else Text(N_("Read all parameters of {count} nodes"), count=len(nodes)))

    async def run(job: Job) -> None:
        job.result["values"] = {}
        try:
            await asyncio.gather(*(read_node(session, node, work[node.node_id], job, ctx) for node in nodes))
        except TransportError as exc:  # the adapter is gone: stop, keep what was read, say how far it got
            read = sum(len(values) for values in job.result["values"].values())
            raise TransportError(Text(N_("{why}, {read} of {total} parameters read before"), why=said(exc),
                                      read=read, total=total), hint=exc.hint) from exc

    # The same read asked again while it runs follows the running job (a read-all is minutes of bus work per node).
    same_as = f"read {session.id} {sorted(work)} {group or '*'} {parameter_set}"
    return jobs.start("read", title, total, run, same_as=same_as, failures_leave_incomplete=True)
