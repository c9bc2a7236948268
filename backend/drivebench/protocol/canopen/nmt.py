"""NMT commands and states (CiA 301), in the manuals' words: English, marked N_() for the catalogue (a state word is
also a CSS class and an API value; a page shows ``_(label)``)."""

from __future__ import annotations

from enum import IntEnum

from drivebench.i18n import N_


class NmtCommand(IntEnum):
    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82

    @property
    def label(self) -> str:
        return NMT_COMMAND_NAMES[self]


NMT_COMMAND_NAMES = {
    NmtCommand.START: N_("Start remote node"),
    NmtCommand.STOP: N_("Stop remote node"),
    NmtCommand.ENTER_PRE_OPERATIONAL: N_("Enter pre-operational"),
    NmtCommand.RESET_NODE: N_("Reset node"),
    NmtCommand.RESET_COMMUNICATION: N_("Reset communication"),
}


class NmtState(IntEnum):
    """The state byte of heartbeat and boot-up telegrams."""

    BOOTUP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F

    @property
    def label(self) -> str:
        return NMT_STATE_NAMES[self]


NMT_STATE_NAMES = {
    NmtState.BOOTUP: N_("Boot-up"),
    NmtState.STOPPED: N_("Stopped"),
    NmtState.OPERATIONAL: N_("Operational"),
    NmtState.PRE_OPERATIONAL: N_("Pre-operational"),
}

# The state a node is in after each command.
STATE_AFTER = {
    NmtCommand.START: NmtState.OPERATIONAL,
    NmtCommand.STOP: NmtState.STOPPED,
    NmtCommand.ENTER_PRE_OPERATIONAL: NmtState.PRE_OPERATIONAL,
    NmtCommand.RESET_NODE: NmtState.PRE_OPERATIONAL,
    NmtCommand.RESET_COMMUNICATION: NmtState.PRE_OPERATIONAL,
}

COMMAND_BY_NAME = {
    "start": NmtCommand.START,
    "stop": NmtCommand.STOP,
    "pre-operational": NmtCommand.ENTER_PRE_OPERATIONAL,
    "reset-node": NmtCommand.RESET_NODE,
    "reset-communication": NmtCommand.RESET_COMMUNICATION,
}


def nmt_frame(command: NmtCommand, node_id: int) -> bytes:
    """COB-ID 0x000 data: command specifier + node id (0 = all nodes)."""
    return bytes([int(command), node_id])
