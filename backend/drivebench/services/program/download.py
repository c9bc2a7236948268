"""Program download as a job: the checked file confirmed for its node, the program stopped (0x1F51 = 0), the image
sent to 0x1F50 (block transfer, segmented where the device refuses it) with bytes, rate and ETA on the job, the
program started (0x1F51 = 1) and the new software identification (0x1F56) read and compared; a cancel aborts the
transfer on the bus. The node's lease is held throughout; every write is in the audit log."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from dataclasses import asdict

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.profile import Access, ObjectEntry
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import Conflict, DriveBenchError, SdoAbortError
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.network import NodeClient
from drivebench.protocol.canopen.program_objects import PROGRAM_CONTROL, PROGRAM_DATA, SOFTWARE_ID, ProgramCommand
from drivebench.protocol.canopen.sdo_domain import ABORT_BY_CLIENT, TransferCancelled
from drivebench.protocol.datatypes import DataType
from drivebench.services.bus.sessions import Session
from drivebench.services.control.drive_guard import guard_for
from drivebench.services.params import node_lease
from drivebench.services.params.jobs import Job, JobManager, JobState, said
from drivebench.services.params.session_part import on_bus, service
from drivebench.services.params.values import WriteResult
from drivebench.services.params.write_context import Values, WriteContext
from drivebench.services.params.write_ports import WriteAttempt
from drivebench.services.params.writes import send_logged
from drivebench.services.program.firmware import FirmwareFile, refusal
from drivebench.services.program.program_info import canopen_client, program_info, read_u32
from drivebench.services.program.uploads import CHECKED

PROGRAM_ORIGIN = "program download"
BOOT_WAIT_S = 5.0
_DATA_ITEM = Item("0x1F50.1", PROGRAM_DATA, 1, ObjectEntry(name="Program data", data_type=DataType.DOMAIN,
                                                            access=Access.WO, index=PROGRAM_DATA, subindex=1))
COMMAND_WORDS = {ProgramCommand.STOP: N_("stop"), ProgramCommand.START: N_("start"),
                 ProgramCommand.RESET: N_("reset"), ProgramCommand.CLEAR: N_("clear")}


def download_values(firmware: FirmwareFile) -> Values:
    """What a download sends, as its confirmation repeats it."""
    return {"0x1F50 Program data": f"{firmware.name} ({len(firmware.image)} bytes, CRC32 0x{firmware.crc32:08X})",
            "0x1F51 Program control": "0 stop, 1 start"}


def control_values(command: ProgramCommand) -> Values:
    return {"0x1F51 Program control": f"{int(command)} {command.name.lower()}"}


async def node_identity(session: Session, node_id: int) -> tuple[int | None, int | None, str]:
    """Vendor and product the node reports (0x1018 sub 1, 2), else what the scan or the profile said."""
    client = canopen_client(session, node_id)
    try:
        return await read_u32(client, 0x1018, 1), await read_u32(client, 0x1018, 2), "0x1018"
    except DriveBenchError:
        node = session.node(node_id)
        known = node.identity
        profile = node.profile.identity if node.profile is not None else None
        vendor = known.get("vendor_id", profile.vendor_id if profile else None)
        product = known.get("product_code", profile.product_code if profile else None)
        return vendor, product, "profile"


async def check(session: Session, node_id: int, firmware: FirmwareFile) -> dict[str, object]:
    """The file against the node: kept for a download when nothing refuses it."""
    vendor, product, source = await node_identity(session, node_id)
    refused = refusal(firmware, vendor, product)
    notes = []
    if not {"vendor_id", "product_code"} & set(firmware.identity):
        notes.append(_("The file carries no identification: DriveBench cannot tell which product it is for. Make "
                       "sure it is the firmware for this device."))
    file_id = None if refused else (await asyncio.to_thread(CHECKED.add, session.id, node_id, firmware)).id
    return {"file_id": file_id, "ok": refused is None, "refused": refused, "notes": notes,
            "file": firmware.summary(), "node": {"node_id": node_id, "identity_from": source,
                                                   "vendor_id": None if vendor is None else f"0x{vendor:08X}",
                                                   "product_code": None if product is None else f"0x{product:08X}"},
            "confirm_values": None if refused else download_values(firmware)}


async def control(session: Session, node_id: int, command: ProgramCommand, ctx: WriteContext) -> dict[str, object]:
    """One 0x1F51 command, confirmed (0x1F51 is a moving object: start runs the program) and under the lease."""
    canopen_client(session, node_id)
    confirmed = service(session).moving_writes.confirm(
        ctx, node_id, _("Program control ({command})").format(command=_(COMMAND_WORDS[command])),
        control_values(command))
    with node_lease.writing(session, node_id, confirmed):
        await send_logged(session, node_id, PROGRAM_CONTROL, 1, bytes([command]),
                          ctx=confirmed.as_origin(PROGRAM_ORIGIN))
    return asdict(await program_info(session, node_id))


async def checked_file(session: Session, node_id: int, file_id: str) -> FirmwareFile:
    """The file :func:`check` kept for the node under ``file_id`` (404 in words when there is none)."""
    return (await asyncio.to_thread(CHECKED.get, file_id, session.id, node_id)).firmware


def start_download(session: Session, node_id: int, jobs: JobManager, firmware: FirmwareFile, ctx: WriteContext
                   ) -> Job:
    """Checks, then the job: 409 while the drive is enabled or another writer holds the node, 428 unconfirmed.
    ``firmware``: a file :func:`check` kept for the node (:func:`checked_file`)."""
    client = canopen_client(session, node_id)
    if guard_for(session).armed(node_id):
        raise Conflict(_("Node {node} is enabled from a control panel: stop the drive before a program "
                         "download.").format(node=node_id))
    confirmed = service(session).moving_writes.confirm(
        ctx, node_id, _("The program download of {file}").format(file=firmware.name), download_values(firmware))
    confirmed = confirmed.as_origin(PROGRAM_ORIGIN)
    writer = confirmed.writer
    table = node_lease.leases(session)
    if writer is None:
        table.check(node_id)
    else:
        table.acquire(node_id, writer, hold=True)
    profile = session.node(node_id).profile
    block = profile is None or profile.features.block_sdo

    async def work(job: Job) -> None:
        try:
            await _download(session, node_id, client, firmware, job, confirmed, block)
        finally:
            if writer is not None:
                table.done(node_id, writer)

    title = Text(N_("Program download of {file} to node {node}"), file=firmware.name, node=node_id)
    return jobs.start("program-download", title, len(firmware.image), work, same_as=f"program:{session.id}:{node_id}")


async def _audited_data(session: Session, node_id: int, firmware: FirmwareFile, ctx: WriteContext,
                        send: asyncio.Future[str]) -> str:
    audits = service(session).write_audits
    shown = download_values(firmware)["0x1F50 Program data"]
    new = from_raw(_DATA_ITEM.entry, str(shown))
    attempt = WriteAttempt(session, node_id, _DATA_ITEM, None, new, ctx)
    tokens = [(audit, await audit.sending(attempt)) for audit in audits]
    try:
        mode = await send
    except BaseException as exc:
        for audit, token in tokens:
            await asyncio.shield(audit.done(token, None, exc))
        raise
    for audit, token in tokens:
        await audit.done(token, WriteResult(_DATA_ITEM.ref, new, None, None, None, False), None)
    return mode


async def _download(session: Session, node_id: int, client: NodeClient, firmware: FirmwareFile, job: Job,
                    ctx: WriteContext, block: bool) -> None:
    result = job.result
    result.update(file=firmware.summary(), node_id=node_id, phase="stop")
    with contextlib.suppress(DriveBenchError):
        result["software_id_before"] = f"0x{await read_u32(client, SOFTWARE_ID):08X}"
    await send_logged(session, node_id, PROGRAM_CONTROL, 1, bytes([ProgramCommand.STOP]), ctx=ctx)
    result["phase"] = "download"
    loop = asyncio.get_running_loop()
    cancelled = threading.Event()

    def progress(sent: int) -> None:
        loop.call_soon_threadsafe(lambda: job.advance(max(sent - job.done, 0)))

    transfer = asyncio.ensure_future(on_bus(lambda: client.download_domain(
        PROGRAM_DATA, 1, firmware.image, block=block, progress=progress, cancelled=cancelled)))
    try:
        result["transfer"] = await asyncio.shield(_audited_data(session, node_id, firmware, ctx, transfer))
    except asyncio.CancelledError:
        cancelled.set()
        with contextlib.suppress(Exception):
            await transfer
        result["outcome"] = Text(N_("Cancelled after {sent} bytes: the transfer was aborted (SDO abort 0x{code:08X}); "
                                    "the device keeps no part of it. Download again before starting the program."),
                                 sent=job.done, code=ABORT_BY_CLIENT)
        raise
    except TransferCancelled:
        raise asyncio.CancelledError from None
    except SdoAbortError as exc:
        await _failed(session, node_id, job, Text(N_("The device refused the program ({reason})"), reason=exc.detail))
        return
    except DriveBenchError as exc:
        await _failed(session, node_id, job, Text(N_("The device stopped answering during the download ({reason})"),
                                                  reason=said(exc)), wait_s=BOOT_WAIT_S)
        return
    result["phase"] = "start"
    await send_logged(session, node_id, PROGRAM_CONTROL, 1, bytes([ProgramCommand.START]), ctx=ctx)
    info = await program_info(session, node_id)
    result["info"] = asdict(info)
    result["software_id"] = info.software_id
    expected = firmware.identity.get("software_id")
    result["phase"] = "done"
    if expected is not None and info.software_id != f"0x{expected:08X}":
        job.conclude(JobState.FAILED, Text(N_("The device reports software identification {found} after the start, "
                                              "the file names {expected}"), found=info.software_id,
                                           expected=f"0x{expected:08X}"))
    elif not info.flash_ok:
        job.conclude(JobState.FAILED, Text(N_("Flash status after the start: {status}"), status=info.flash_text))
    else:
        result["verified"] = expected is not None or info.software_id != result.get("software_id_before")
        result["outcome"] = Text(N_("Program started; software identification {id}"), id=info.software_id)


async def _failed(session: Session, node_id: int, job: Job, why: str, wait_s: float = 0.0) -> None:
    """The download failed: the device's flash status in words and what to do next (a device that lost power comes
    back in its bootloader: it is asked again for ``wait_s``)."""
    deadline = asyncio.get_running_loop().time() + wait_s
    while True:
        try:
            info = await program_info(session, node_id)
            break
        except DriveBenchError as exc:
            if asyncio.get_running_loop().time() >= deadline:
                job.conclude(JobState.FAILED, Text(N_("{why}; the device does not answer its program objects "
                                                      "either ({reason})."), why=why, reason=said(exc)))
                return
            await asyncio.sleep(0.3)
    job.result["info"] = asdict(info)
    step = f" {info.next_step}" if info.next_step else ""
    job.conclude(JobState.FAILED, Text(N_("{why}. Flash status: {status}.{step}"), why=why,
                                       status=info.flash_text, step=step))
