"""canopen's SDO communication errors in words a user can act on.

canopen 2.4.1 raises one ``SdoCommunicationError`` for silence, a toggle bit mismatch, an answer for another
object and an unexpected command, telling them apart only by message. This module reads the message once and
answers the matching error of our tree; :func:`read_segments` also counts how far a segmented upload got.
"""

from __future__ import annotations

import re

import canopen
from canopen.sdo.exceptions import SdoCommunicationError

from drivebench.errors import ProtocolError, SdoOutOfStepError, SdoStalledError, SdoTimeoutError
from drivebench.i18n import N_, Text

SEGMENT_DATA = 7
_OTHER_OBJECT = re.compile(r"value for 0x([0-9A-Fa-f]{1,4}):([0-9A-Fa-f]{1,2}) instead")


class SegmentsLost(SdoCommunicationError):
    """A segmented upload failed after its start was answered: ``done`` of ``total`` segments arrived."""

    def __init__(self, cause: SdoCommunicationError, done: int, total: int | None) -> None:
        super().__init__(str(cause))
        self.done = done
        self.total = total


def read_segments(client: canopen.sdo.SdoClient, index: int, subindex: int) -> bytes:
    """``client.upload`` (expedited or segmented; our clients have an empty object dictionary, so nothing is
    truncated), raising :class:`SegmentsLost` with the progress when the segments stop or go wrong."""
    with client.open(index, subindex, "rb", buffering=0) as stream:
        try:
            return bytes(stream.read())
        except SegmentsLost:
            raise
        except SdoCommunicationError as exc:
            size = stream.size
            total = -(-size // SEGMENT_DATA) if size else None
            raise SegmentsLost(exc, stream.tell() // SEGMENT_DATA, total) from exc


# canopen's messages (canopen/sdo/client.py) in words of the catalogue; a message not known here is shown as it is.
NO_RESPONSE = "No SDO response received"
_REASONS = {
    NO_RESPONSE: N_("No SDO response received"),
    "CRC is not OK": N_("the CRC of the block transfer is wrong"),
    "Some data was lost and could not be retransmitted": N_("block segments were lost and not sent again"),
    "Server did not end transfer as expected": N_("the node did not end the block transfer as expected"),
    "Server did not respond with a block download response": N_("the node did not answer with a block download "
                                                                "response"),
    "Block download unsuccessful": N_("the block download did not succeed"),
}
_UNEXPECTED = re.compile(r"Unexpected response 0x([0-9A-Fa-f]{2})(?: \(expected 0x([0-9A-Fa-f]{2})\))?")
UNEXPECTED = N_("unexpected response {command}")
UNEXPECTED_INSTEAD = N_("unexpected response {command} (expected {expected})")
FAILED = N_("Node {node}, {object}: {reason}")


def reason(text: str) -> str:
    """canopen's message ``text`` in words that each reader gets in their language, where it is one we know."""
    known = _REASONS.get(text)
    if known is not None:
        return Text(known)
    unexpected = _UNEXPECTED.fullmatch(text)
    if unexpected is not None:
        command = f"0x{unexpected.group(1).upper()}"
        if unexpected.group(2):
            return Text(UNEXPECTED_INSTEAD, command=command, expected=f"0x{unexpected.group(2).upper()}")
        return Text(UNEXPECTED, command=command)
    return text


def communication_error(exc: SdoCommunicationError, *, node: int, index: int, subindex: int) -> ProtocolError:
    """The error of our tree for one of canopen's communication errors."""
    text = str(exc)
    silent = "No SDO response" in text or "timeout" in text.lower()
    if isinstance(exc, SegmentsLost) and silent:
        return SdoStalledError(node=node, index=index, subindex=subindex, done=exc.done, total=exc.total)
    where = f"0x{index:04X}sub{subindex}"
    if silent:
        return SdoTimeoutError(Text(SdoTimeoutError.NO_ANSWER, node=node, object=where, reason=reason(text)),
                               node=node, index=index, subindex=subindex)
    if "Toggle bit" in text:
        return SdoOutOfStepError(SdoOutOfStepError.TOGGLE, node=node, index=index, subindex=subindex)
    other = _OTHER_OBJECT.search(text)
    if other is not None:
        return SdoOutOfStepError(SdoOutOfStepError.OTHER_OBJECT, node=node, index=index, subindex=subindex,
                                 answered=(int(other.group(1), 16), int(other.group(2), 16)))
    if text.startswith("Unexpected response"):
        return SdoOutOfStepError(reason(text), node=node, index=index, subindex=subindex)
    return ProtocolError(Text(FAILED, node=node, object=where, reason=reason(text)))

