"""Two devices with one node id: what gives them away, in words.

CAN cannot tell two transmitters of the same COB-ID apart, so a duplicate node id shows only in its effects:

- two boot-up messages from one id within ``BOOTUP_WINDOW_S`` (both devices reset on one NMT command or power-up);
- heartbeats arriving at (about) twice the producer rate the node was configured with (0x1017);
- two answers to one SDO request (the probe after a scan: CiA 301 allows exactly one server per SDO channel).

A finding is kept ``hold_s`` after its last evidence; a probe that gets one answer clears it at once.
"""

from __future__ import annotations

import threading
import time
from collections import deque

import can

from drivebench.i18n import N_, Text, _, shown
from drivebench.protocol.canopen.network import CanopenNetwork

BOOTUP_WINDOW_S = 0.5
HEARTBEATS_JUDGED = 7
"""Heartbeats of one node over which the rate is judged."""
DOUBLED_RATE_FACTOR = 0.65
"""Heartbeats count as doubled when their span is below this share of what the producer period predicts."""
PROBE_WAIT_S = 0.3
"""Time left for a second answer after the last node's first one; longer when the first answers were slow (a loaded
machine or a busy bus slows the duplicate as much): a fixed window read a late second answer as "one answer" and
cleared a real finding."""
FIRST_ANSWER_WAIT_S = 2.0
"""The most the probe waits for each node's first answer (the scan found them, so they are expected to answer)."""
QUIET_S = 0.2
QUIET_MAX_S = 2.0
"""Before the probe asks: the silence it waits for on the answer channels, and the most it waits for it."""
IDENTITY_SERIAL = bytes([0x40, 0x18, 0x10, 0x04, 0, 0, 0, 0])
"""SDO upload request for 0x1018sub4 (serial number)."""


def _quiet(answers: dict[int, list[tuple[float, bytes]]], answered: threading.Condition) -> None:
    """Wait until no answer for 0x1018sub4 came for ``QUIET_S`` (at most ``QUIET_MAX_S``), then forget those that
    came: a duplicate whose SDO server was slow sends its second answer to the scan's own 0x1018sub4 read after the
    scan ended, and one sent after the probe's request is stamped after it too (CI: "3 answers" for two devices)."""
    deadline = time.monotonic() + QUIET_MAX_S
    with answered:
        while time.monotonic() < deadline:
            seen = sum(map(len, answers.values()))
            answered.wait(timeout=QUIET_S)
            if sum(map(len, answers.values())) == seen:
                break
        for stale in answers.values():
            stale.clear()


def _answers_to_this_request(stamped: list[tuple[float, bytes]], asked_at: float) -> list[bytes]:
    """The answers stamped after the request went out. An answer stamped before it answers an earlier request for the
    same object (the scan's own 0x1018sub4 read, or a retried one): it was only handled late, by a notifier thread
    that got no CPU for a while. Frame stamps are on the adapter's clock: where no answer is stamped after the
    request, that clock is not this machine's (a gateway's own), and every answer counts."""
    fresh = [data for stamp, data in stamped if stamp >= asked_at]
    return fresh or [data for _stamp, data in stamped]


class DuplicateWatch(can.Listener):
    """Collects the evidence of duplicate node ids on one session's bus (listener on the notifier thread)."""

    def __init__(self, hold_s: float = 30.0) -> None:
        self.hold_s = hold_s
        self.producer_period_s: dict[int, float] = {}
        """Heartbeat producer time per node as configured (0x1017), read by the session's scan."""
        self._bootups: dict[int, float] = {}
        self._beats: dict[int, deque[float]] = {}
        self._found: dict[int, dict[str, tuple[str, float]]] = {}
        """node id -> kind of evidence -> (words, monotonic time)"""
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        cob_id = msg.arbitration_id
        if msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame or not 0x701 <= cob_id <= 0x77F:
            return
        if not msg.data:
            return
        # spans from the frames' own time stamps: a reader that lagged and catches up must not look like a double
        node_id, now, stamp = cob_id - 0x700, time.monotonic(), msg.timestamp or time.time()
        with self._lock:
            if msg.data[0] == 0:
                last = self._bootups.get(node_id)
                self._bootups[node_id] = stamp
                if last is not None and 0 <= stamp - last < BOOTUP_WINDOW_S:
                    self._note(node_id, "boot-up", Text(N_("two boot-ups {ms} ms apart"),
                                                         ms=f"{1000 * (stamp - last):.0f}"), now)
                return
            beats = self._beats.setdefault(node_id, deque(maxlen=HEARTBEATS_JUDGED))
            beats.append(stamp)
            period = self.producer_period_s.get(node_id)
            if period and len(beats) == HEARTBEATS_JUDGED:
                span = beats[-1] - beats[0]
                if span < DOUBLED_RATE_FACTOR * period * (HEARTBEATS_JUDGED - 1):
                    rate = (HEARTBEATS_JUDGED - 1) / span if span > 0 else float("inf")
                    self._note(node_id, "heartbeat", Text(N_("heartbeats at {rate}/s where node {node} produces one "
                                                              "every {ms} ms"), rate=f"{rate:.1f}", node=node_id,
                                                           ms=f"{period * 1000:.0f}"), now)

    def _note(self, node_id: int, kind: str, evidence: str, now: float) -> None:
        self._found.setdefault(node_id, {})[kind] = (evidence, now)

    def probe(self, network: CanopenNetwork, node_ids: list[int]) -> dict[int, int]:
        """Ask each node once for its serial number (0x1018sub4) and count the answers (blocking). Two or more:
        a duplicate; exactly one clears an earlier finding. Returns the answers per node."""
        answers: dict[int, list[tuple[float, bytes]]] = {node_id: [] for node_id in node_ids}
        answered = threading.Condition()

        def on_answer(can_id: int, data: bytearray, timestamp: float) -> None:
            if bytes(data[1:4]) != IDENTITY_SERIAL[1:4]:
                return  # a late answer to an earlier request (a duplicate's second answer to the scan's 0x1017 read)
            with answered:
                answers[can_id - 0x580].append((timestamp, bytes(data)))
                answered.notify_all()

        locks = [channel.lock for client in list(network.nodes.values()) for channel in client.channels]
        for lock in locks:  # no probe may land in the middle of a transfer
            lock.acquire()
        try:
            for node_id in node_ids:
                network.canopen.subscribe(0x580 + node_id, on_answer)
            try:
                _quiet(answers, answered)  # a duplicate's late second answer to the scan's own read comes first
                sent, asked_at = time.monotonic(), time.time()
                for node_id in node_ids:
                    network.send(0x600 + node_id, IDENTITY_SERIAL)
                with answered:
                    all_answered = answered.wait_for(lambda: all(answers.values()), timeout=FIRST_ANSWER_WAIT_S)
                slowest_first = time.monotonic() - sent if all_answered else 0.0  # a silent node: waited enough
                time.sleep(max(PROBE_WAIT_S, 2 * slowest_first))
            finally:
                for node_id in node_ids:
                    network.canopen.unsubscribe(0x580 + node_id, on_answer)
        finally:
            for lock in locks:
                lock.release()
        now = time.monotonic()
        counted = {node_id: _answers_to_this_request(stamped, asked_at) for node_id, stamped in answers.items()}
        with self._lock:
            for node_id, frames in counted.items():
                if len(frames) >= 2:
                    serials = {int.from_bytes(frame[4:8], "little") for frame in frames if frame[0] & 0xE0 == 0x40}
                    which = (Text(N_("two answers to one SDO request with different serial numbers ({serials})"),
                                   serials=", ".join(f"{s}" for s in sorted(serials))) if len(serials) > 1
                             else Text(N_("{count} answers to one SDO request"), count=len(frames)))
                    self._note(node_id, "sdo", which, now)
                elif len(frames) == 1:
                    self._found.pop(node_id, None)
                    self._bootups.pop(node_id, None)
                    self._beats.pop(node_id, None)
        return {node_id: len(frames) for node_id, frames in counted.items()}

    def found(self) -> dict[int, str]:
        """Node id -> the evidence in words, from findings younger than ``hold_s``."""
        now = time.monotonic()
        found: dict[int, str] = {}
        with self._lock:
            for node_id, kinds in sorted(self._found.items()):
                fresh = [shown(words) for words, at in kinds.values() if now - at <= self.hold_s]
                if fresh:
                    found[node_id] = "; ".join(fresh)
        return found

    def text(self) -> str | None:
        found = self.found()
        if not found:
            return None
        return " ".join(_("Two devices answer as node {node}: {evidence}. Give one of them another node id; until "
                          "then neither can be trusted.").format(node=node_id, evidence=evidence)
                        for node_id, evidence in found.items())
