"""Device commands: save, restore defaults, reset node, the way the device's profile offers them (its ``commands``
section, else CiA 301's objects); a command whose write can move the drive needs the confirmation like any write
(:mod:`drivebench.device.drive.motion`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from functools import partial

from drivebench.device.drive.motion import judge
from drivebench.device.profiles.addressing import IndexRef, parse_ref
from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.commands import CIA301_RESTORE, CIA301_SAVE, CommandWrite
from drivebench.errors import Conflict
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.protocol.datatypes import encode
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import node_lease
from drivebench.services.params.lookup import writable_item
from drivebench.services.params.session_part import on_bus, service
from drivebench.services.params.write_context import WriteContext
from drivebench.services.params.writes import sent_values


class DeviceCommand(StrEnum):
    SAVE = "save"
    RESTORE_DEFAULTS = "restore-defaults"
    RESET_NODE = "reset-node"


@dataclass(frozen=True)
class CommandResult:
    command: DeviceCommand
    via: str
    """What was sent: ``C00002/11 = 1``, ``0x1010.1 = 'save'``, ``NMT reset node``."""
    detail: str


def _command_write(node: SessionNode, catalog: Catalog | None, which: DeviceCommand) -> CommandWrite | None:
    """The profile's own write for ``which`` (its ``commands`` section), else CiA 301's where the device has it."""
    section = node.profile.commands if node.profile is not None else None
    own = None if section is None else section.save if which is DeviceCommand.SAVE else section.restore_defaults
    if own is not None:
        return own
    standard = CIA301_SAVE if which is DeviceCommand.SAVE else CIA301_RESTORE
    return standard if catalog is None or writable_item(catalog, standard.ref) is not None else None


async def command(session: Session, node_id: int, which: DeviceCommand, *, ctx: WriteContext) -> CommandResult:
    session.node(node_id)
    with node_lease.writing(session, node_id, ctx):
        return await _command(session, node_id, which, ctx)


async def _command(session: Session, node_id: int, which: DeviceCommand, ctx: WriteContext) -> CommandResult:
    node = session.node(node_id)
    catalog = node.catalog
    client = session.client(node_id)
    if which is DeviceCommand.RESET_NODE:
        await session.nmt(NmtCommand.RESET_NODE, node_id)
        return CommandResult(which, "NMT reset node",
                             Text(N_("Node {node} resets; unsaved changes are lost."), node=node_id))
    write = _command_write(node, catalog, which)
    if write is None:
        raise Conflict(_("{device} offers no {command} command in its profile (no CiA 301 object, no commands "
                         "section)").format(device=node.device_name, command=_command_name(which)))
    item = writable_item(catalog, write.ref)
    if item is not None:
        index, subindex, data = item.index, item.subindex, encode(item.entry.data_type, write.raw)
        if judge(item, write.raw, node.profile).moving:  # a profile's command is a write like any other
            service(session).moving_writes.admit(ctx, node_id, _("The {command} command ({via})").format(
                command=_command_name(which), via=write.via), sent_values(item, write.raw))
    elif catalog is None:  # no profile: the CiA 301 object, addressed as such
        parsed = parse_ref(write.ref)
        assert isinstance(parsed, IndexRef)  # CIA301_SAVE / CIA301_RESTORE
        index, subindex, data = parsed.index, parsed.subindex or 0, write.raw.to_bytes(4, "little")
    else:
        raise Conflict(_("{device}: the profile's {command} command writes {ref}, which the profile does not list as "
                         "a writable entry").format(device=node.device_name, command=_command_name(which),
                                                    ref=write.ref))
    await on_bus(partial(client.download, index, subindex, data))
    if write.after_reset:
        node.pending_reset.add("restore defaults")
    return CommandResult(which, write.via, Text(write.done, node=node_id))


def _command_name(which: DeviceCommand) -> str:
    return {DeviceCommand.SAVE: _("save"), DeviceCommand.RESTORE_DEFAULTS: _("restore defaults"),
            DeviceCommand.RESET_NODE: _("reset node")}[which]

