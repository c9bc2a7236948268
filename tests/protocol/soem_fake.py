"""A stand-in for pysoem's ``Master``/``CdefSlave`` API, for the direct master's segment logic.

Nothing real can run that part here: this machine has no EtherCAT network card and no slave answering raw EtherCAT
frames (SOEM talks to the ESC's registers and SyncManagers; building a raw-frame slave is out of scope). So the
stand-in answers pysoem's calls from the simulator's real 8400 motec EtherCAT unit (:class:`SimulatedSlave`: its CoE
SDO server byte for byte, the manual's state machine and AL status codes, the Pre-Operational-only PDO mapping) and
raises pysoem's **real** exception classes (``SdoError``, ``WkcError``, ``Emergency`` ...), so the mapping of each
into the tool's errors is tested against the classes SOEM raises. What the stand-in adds of its own is written down
below: SOEM's station addresses (0x1000 + position) and an ESC refusing Safe-Operational before the process data is
mapped (AL status code 0x001D, as a real slave without SyncManager 2/3 does).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from drivebench.errors import SdoAbortError, SdoTimeoutError
from drivebench.protocol.ethercat import coe, esm
from drivebench.protocol.ethercat.coe_sdo import CoeSdoClient
from drivebench.simulator.ethercat import SimulatedSlave

pysoem = pytest.importorskip("pysoem")


class FakeSlave:
    def __init__(self, master: FakeMaster, position: int, unit: SimulatedSlave) -> None:
        self.master = master
        self.position = position
        self.unit = unit
        identity = unit.node.profile.identity
        self.name, self.man, self.id, self.rev = unit.name, identity.vendor_id, identity.product_code, \
            identity.revision or 0
        self.state = 0
        self.callbacks: list[Any] = []
        self.emergencies: list[bytes] = []
        unit.emergency_sink = self.emergencies.append
        self.sdo = CoeSdoClient(lambda telegram, timeout: next(iter(unit.mailbox(telegram)), None), unit.station,
                                retries=0)

    def _answering(self) -> None:
        if not self.unit.node.powered:
            raise pysoem.WkcError(wkc=0)

    def _fprd(self, address: int, size: int, timeout_us: int = 2000) -> bytes:
        self._answering()
        value = {0x0010: 0x1000 + self.position, 0x0130: self.unit.al_status, 0x0134: self.unit.status_code}[address]
        return value.to_bytes(size, "little")

    def write_state(self) -> int:
        self._answering()
        target = self.state & 0x0F
        if target >= esm.EsmState.SAFE_OPERATIONAL and not self.master.mapped \
                and self.unit.state is esm.EsmState.PRE_OPERATIONAL:
            self.unit.error, self.unit.status_code = True, 0x001D  # SyncManager 2/3 not configured
            return 1
        self.unit.request_state(target)
        return 1

    def state_check(self, expected: int, timeout: int = 2000) -> int:
        return self.unit.al_status & 0x0F

    def sdo_read(self, index: int, subindex: int, size: int = 0, ca: bool = False) -> bytes:
        return self._sdo(index, subindex, lambda: self.sdo.upload(index, subindex))

    def sdo_write(self, index: int, subindex: int, data: bytes, ca: bool = False) -> None:
        self._sdo(index, subindex, lambda: self.sdo.download(index, subindex, data))

    def _sdo(self, index: int, subindex: int, call: Any) -> Any:
        self._answering()
        try:
            return call()
        except SdoAbortError as exc:
            raise pysoem.SdoError(self.position, index, subindex, exc.abort_code, "SOEM's text") from exc
        except SdoTimeoutError as exc:
            raise pysoem.WkcError(wkc=0) from exc
        finally:
            self.mbx_receive()

    def mbx_receive(self) -> int:
        while self.emergencies:
            body = coe.CoeMessage.decode(coe.Mailbox.decode(self.emergencies.pop(0)).data).body
            code, register, data = coe.parse_emergency(body)
            emergency = pysoem.Emergency(self.position, code, register, data[0], int.from_bytes(data[1:3], "little"),
                                         int.from_bytes(data[3:5], "little"))
            for callback in self.callbacks:
                callback(emergency)
        return 1

    def add_emergency_callback(self, callback: Any) -> None:
        self.callbacks.append(callback)


class FakeMaster:
    units: list[SimulatedSlave] = []

    def __init__(self) -> None:
        self.slaves: list[FakeSlave] | None = None
        self.mapped = False
        self.cycles = 0
        self.opened = ""
        self.closed = False

    def open(self, ifname: str) -> None:
        self.opened = ifname

    def config_init(self) -> int:
        self.mapped = False
        powered = [unit for unit in self.units if unit.node.powered]
        for unit in powered:
            unit.request_state(esm.EsmState.INIT)
        self.slaves = [FakeSlave(self, position, unit) for position, unit in enumerate(powered, start=1)]
        return len(self.slaves) or -1

    def config_map(self) -> int:
        self.mapped = True
        return 8

    def send_processdata(self) -> int:
        self.cycles += 1
        return 1

    def receive_processdata(self, timeout: int = 2000) -> int:
        return 3

    def close(self) -> None:
        self.closed = True


def fake_pysoem(units: list[SimulatedSlave]) -> Any:
    """pysoem as a module: the stand-in master over ``units``, pysoem's real exception classes."""
    master = type("Master", (FakeMaster,), {"units": units})
    return SimpleNamespace(Master=master, SdoError=pysoem.SdoError, WkcError=pysoem.WkcError,
                           MailboxError=pysoem.MailboxError, PacketError=pysoem.PacketError,
                           ConfigMapError=pysoem.ConfigMapError)
