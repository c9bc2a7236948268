"""canopen's blocking SDO client, taking as an answer only a frame that answers the request it waits for.

canopen 2.4.1's ``SdoClient.request_response`` sends a request again after ``RESPONSE_TIMEOUT`` and empties its
response queue only when the *next* request starts. A healthy node that was only slow (a busy device, a loaded host)
answers both attempts; the second answer can arrive after the next request was sent and be taken as its answer
(issue 29: a 0x1F51 write failed with "unexpected response 0x43", the late second answer to the 0x1F56 read before
it). Here the answer to a request that starts a transfer (expedited or the initiate of a segmented or block one)
must name the request's object and be of the request's kind, or be an abort naming that object; anything else is
stale, dropped (logged at debug), and the wait goes on for the real answer within the same timeout and attempts.
Frames inside a transfer (segments, block acknowledgements) carry no object and are taken as before.

When an attempt hears only stale frames, the error names the first one the way canopen would have (an answer for
another object, an unexpected command), so a device that really answers out of step is still told in those words.
"""

from __future__ import annotations

import logging
import queue
import struct
import time

import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

log = logging.getLogger(__name__)

ABORT = 0x80
_ANSWER_KIND = {1: 3, 2: 2}
"""Client command specifier of an expedited/initiate request -> server command specifier of its answer (CiA 301
7.2.4.3: initiate download -> 3, initiate upload -> 2); block initiates in :func:`expected_answer`."""


def object_address(index: int, subindex: int) -> bytes:
    """Bytes 1-3 of a frame that starts or aborts a transfer: the index (little endian) and subindex (CiA 301
    7.2.4.3). Frames inside a transfer carry no object."""
    return struct.pack("<HB", index, subindex)


def names_object(frame: bytes | bytearray, address: bytes) -> bool:
    """Whether ``frame`` names the object at ``address`` (see :func:`object_address`); a frame too short to name
    one (a broken device, another tool on the COB-ID) names none."""
    return len(frame) >= 4 and frame[1:4] == address


def carries_object(frame: bytes | bytearray) -> bool:
    """Whether ``frame`` (an SDO server's answer) names an object: an abort, an initiate answer (expedited or
    segmented upload, download) or a block initiate answer; segments and block acknowledgements carry none."""
    if not frame:
        return False
    command = frame[0]
    return command == ABORT or command >> 5 in (2, 3) or (command >> 5 in (5, 6) and command & 0x03 == 0)


def expected_answer(request: bytes | bytearray) -> tuple[bytes, int] | None:
    """(object bytes 1-3, server command specifier) the answer to ``request`` must carry, or None for a frame
    inside a transfer (no object to match)."""
    if len(request) < 4:
        return None
    command = request[0] >> 5
    kind = _ANSWER_KIND.get(command)
    if command == 5 and request[0] & 0x03 == 0:  # block upload initiate
        kind = 6
    elif command == 6 and request[0] & 0x01 == 0:  # block download initiate
        kind = 5
    return None if kind is None else (bytes(request[1:4]), kind)


class MatchingSdoClient(canopen.sdo.SdoClient):
    """An ``SdoClient`` that passes over late answers to earlier requests (see the module's docstring)."""

    def __init__(self, rx_cobid: int, tx_cobid: int, od: canopen.ObjectDictionary) -> None:
        super().__init__(rx_cobid, tx_cobid, od)
        self._expected: tuple[bytes, int] | None = None

    def request_response(self, sdo_request: bytes | bytearray) -> bytes:
        self._expected = expected_answer(sdo_request)
        try:
            return bytes(super().request_response(sdo_request))
        finally:
            self._expected = None

    def read_response(self) -> bytes:
        expected = self._expected
        if expected is None:
            return bytes(super().read_response())
        deadline = time.monotonic() + float(self.RESPONSE_TIMEOUT)
        stale: bytes | None = None
        while True:
            try:
                response = bytes(self.responses.get(timeout=max(deadline - time.monotonic(), 0.0)))
            except queue.Empty:
                raise SdoCommunicationError(_unanswered(expected, stale)) from None
            if len(response) == 8 and names_object(response, expected[0]) and (
                    response[0] == ABORT or response[0] >> 5 == expected[1]):
                break
            log.debug("SDO 0x%03X: dropped %s, not the answer to the request for %s", self.tx_cobid,
                      response.hex(), expected[0].hex())
            stale = stale or response
        if response[0] == ABORT:
            raise SdoAbortedError(int.from_bytes(response[4:8], "little"))
        return response


def _unanswered(expected: tuple[bytes, int], stale: bytes | None) -> str:
    """canopen's words for an attempt without its answer: silence, or the first frame heard instead."""
    if stale is None or len(stale) < 4:
        return "No SDO response received"
    if stale[1:4] != expected[0]:
        index = stale[1] | stale[2] << 8
        return f"Node returned a value for 0x{index:04X}:{stale[3]:02X} instead"
    return f"Unexpected response 0x{stale[0]:02X}"


class MatchingRemoteNode(canopen.RemoteNode):
    """A ``RemoteNode`` whose SDO channels (the default one and each added) are :class:`MatchingSdoClient`."""

    def add_sdo(self, rx_cobid: int, tx_cobid: int) -> MatchingSdoClient:
        client = MatchingSdoClient(rx_cobid, tx_cobid, self.object_dictionary)
        self.sdo_channels.append(client)
        if self.has_network():
            self.network.subscribe(client.tx_cobid, client.on_response)
        return client
