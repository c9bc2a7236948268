"""Send telegrams as a manual prints them and wait for the answers on a python-can virtual bus."""

from __future__ import annotations

import time
from collections.abc import Callable

import can

ANSWER_TIMEOUT_S = 5.0


class WireScript:
    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus

    def send(self, cob_id: int, data_hex: str) -> None:
        self.bus.send(can.Message(arbitration_id=cob_id, data=bytes.fromhex(data_hex), is_extended_id=False))

    def expect(self, cob_id: int, accept: Callable[[bytes], bool] = lambda data: True,
               timeout_s: float = ANSWER_TIMEOUT_S) -> bytes:
        """The first frame on ``cob_id`` that ``accept`` takes, read from now on."""
        deadline = time.monotonic() + timeout_s
        seen: list[str] = []
        while (left := deadline - time.monotonic()) > 0:
            msg = self.bus.recv(timeout=min(left, 0.2))
            if msg is None or msg.arbitration_id != cob_id:
                continue
            seen.append(bytes(msg.data).hex(" "))
            if accept(bytes(msg.data)):
                return bytes(msg.data)
        raise AssertionError(f"no accepted frame on 0x{cob_id:03X} in {timeout_s} s; seen: {seen[-5:]}")

    def sdo(self, node_id: int, request_hex: str) -> bytes:
        """One SDO request, its answer (the first response on 0x580 + node)."""
        self.drain()
        self.send(0x600 + node_id, request_hex)
        return self.expect(0x580 + node_id)

    def drain(self) -> None:
        while self.bus.recv(timeout=0) is not None:
            pass

    def status_word(self, cob_id: int, word: int, timeout_s: float = ANSWER_TIMEOUT_S) -> bytes:
        """Wait for a PDO whose first two bytes are ``word`` (little-endian)."""
        return self.expect(cob_id, lambda data: data[:2] == word.to_bytes(2, "little"), timeout_s)
