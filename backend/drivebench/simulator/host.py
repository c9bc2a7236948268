"""What a device model (a drive's state machine, the PDO engine) uses of the simulated node that carries it.

The node (:mod:`drivebench.simulator.node`) builds its models and hands itself over as their host; the models know
only this much of it, so they need not import the node.
"""

from __future__ import annotations

from typing import Protocol

from drivebench.device.profiles.profile import Profile
from drivebench.simulator.store import ObjectStore


class DeviceHost(Protocol):
    profile: Profile
    store: ObjectStore

    def send(self, cob_id: int, data: bytes) -> None: ...

    def raise_emcy(self, code: int, register: int = 0x01, vendor: bytes = b"") -> None: ...

    def fault_bytes(self, number: int) -> bytes: ...

    def record_fault(self, number: int) -> None: ...

    def clear_emcy(self) -> None: ...
