"""What a node says about its program: 0x1F51 state, 0x1F56 identification, 0x1F57 flash status, in words, with the
next step where the device waits in its bootloader."""

from __future__ import annotations

from dataclasses import dataclass

from drivebench.errors import Conflict, DriveBenchError
from drivebench.i18n import _
from drivebench.protocol.canopen.network import NodeClient
from drivebench.protocol.canopen.program_objects import (
    FLASH_STATUS,
    PROGRAM_CONTROL,
    SOFTWARE_ID,
    FlashStatus,
    program_state_text,
)
from drivebench.services.bus.sessions import Session
from drivebench.services.params.session_part import on_bus

DEVICE_TYPE = 0x1000
NO_VALID_PROGRAM = 1


@dataclass(frozen=True)
class ProgramInfo:
    node_id: int
    state: int | None
    state_text: str | None
    software_id: str | None
    flash_status: str | None
    flash_text: str | None
    flash_ok: bool
    bootloader: bool
    next_step: str | None


def canopen_client(session: Session, node_id: int) -> NodeClient:
    session.node(node_id)
    client = session.client(node_id).domain_download
    if client is None:
        raise Conflict(_("Program download (CiA 302-3) is for CANopen nodes; node {node} of session {session} is "
                         "not on a CAN bus").format(node=node_id, session=session.id))
    return client


async def read_u32(client: NodeClient, index: int, sub: int = 1) -> int:
    data = await on_bus(lambda: client.upload(index, sub))
    return int.from_bytes(data[:4].ljust(4, b"\x00"), "little")


async def program_info(session: Session, node_id: int) -> ProgramInfo:
    """Reads 0x1F51, 0x1F56 and 0x1F57 (sub 1); a device that answers them but not 0x1000 is in its bootloader."""
    client = canopen_client(session, node_id)
    state = await read_u32(client, PROGRAM_CONTROL)
    software_id = await read_u32(client, SOFTWARE_ID)
    flash = FlashStatus(await read_u32(client, FLASH_STATUS))
    try:
        await read_u32(client, DEVICE_TYPE, 0)
        bootloader = False
    except DriveBenchError:
        bootloader = True
    next_step = None
    if bootloader or flash.error == NO_VALID_PROGRAM or state == 3:
        next_step = _("The device holds no valid program and waits in its bootloader: download the program again, "
                      "then start it.")
    elif flash.error:
        next_step = _("The last flash failed ({reason}): download the program again; if it fails again, the "
                      "device's flash memory may need service.").format(reason=flash.text())
    return ProgramInfo(node_id, state & 0xFF, program_state_text(state & 0xFF), f"0x{software_id:08X}",
                       f"0x{flash.raw:08X}", flash.text(), flash.ok, bootloader, next_step)
