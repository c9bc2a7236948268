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


def communication_error(exc: SdoCommunicationError, *, node: int, index: int, subindex: int) -> ProtocolError:
    """The error of our tree for one of canopen's communication errors."""
    text = str(exc)
    silent = "No SDO response" in text or "timeout" in text.lower()
    if isinstance(exc, SegmentsLost) and silent:
        return SdoStalledError(node=node, index=index, subindex=subindex, done=exc.done, total=exc.total)
    if silent:
        where = f"0x{index:04X}sub{subindex}"
        return SdoTimeoutError(SdoTimeoutError.NO_ANSWER.format(node=node, object=where, reason=text),
                               node=node, index=index, subindex=subindex).keep_template(
            SdoTimeoutError.NO_ANSWER, node=node, object=where, reason=text)
    if "Toggle bit" in text:
        return SdoOutOfStepError("toggle", node=node, index=index, subindex=subindex)
    other = _OTHER_OBJECT.search(text)
    if other is not None:
        return SdoOutOfStepError("object", node=node, index=index, subindex=subindex,
                                 answered=(int(other.group(1), 16), int(other.group(2), 16)))
    if text.startswith("Unexpected response"):
        return SdoOutOfStepError(text.lower(), node=node, index=index, subindex=subindex)
    return ProtocolError(f"Node {node}, 0x{index:04X}sub{subindex}: {text}")
