"""A direct EtherCAT master on a network card of its own, through pysoem (SOEM): the ``drivebench[ethercat]`` extra.

A bus spec ``ethercat:eth1`` names the card. SOEM sends raw Ethernet frames (EtherType 0x88A4), so the process needs
CAP_NET_RAW: run it as root or give its Python the capability (``setcap cap_net_raw+ep``). :func:`refusal` says in
words why a master cannot run here; :class:`SoemLink` wraps pysoem's blocking calls (one at a time: hold ``lock``)
and turns its exceptions into the tool's: an SDO abort (``SdoError`` with the code) -> :class:`SdoAbortError`, no
answer (``WkcError``, working counter 0) -> :class:`SdoTimeoutError`, a mailbox error reply or a wrong frame ->
:class:`ProtocolError`. What the slaves' states and mailboxes mean is the protocol layer's
(:mod:`drivebench.protocol.ethercat.master`).

Emergencies: pysoem hands a slave's CoE emergency to its callbacks while it reads that slave's mailbox (during an SDO
transfer, or :meth:`SoemLink.poll_mailboxes`, which the link's cycle thread calls twice a second).
"""

from __future__ import annotations

import contextlib
import importlib
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from drivebench.errors import BusSpecError, ProtocolError, SdoAbortError, SdoTimeoutError, TransportError
from drivebench.i18n import N_, Text

NET_CLASS = Path("/sys/class/net")
CAP_NET_RAW = 13
STATION_OFFSET = 0x1000
"""SOEM's EC_NODEOFFSET: config_init gives the slave at position p the configured station address 0x1000 + p."""
REG_STATION, REG_AL_STATUS, REG_AL_STATUS_CODE = 0x0010, 0x0130, 0x0134
SDO_BUFFER = 0x10000
"""Bytes pysoem may upload at most (its default is 256; a Lenze string or domain may be longer)."""
CYCLE_S = 0.004
"""Process data period while a slave is Safe-Operational or higher (outputs stay zero)."""
MAILBOX_POLL_S = 0.5
INSTALL = "pip install 'drivebench[ethercat]'"
_NIC_RE = re.compile(r"^ethercat:(?P<nic>[A-Za-z0-9_.:-]{1,32})$")

EmergencyHandler = Callable[[int, int, int, bytes, float], None]
"""(position, error code, error register, 5 data bytes, time)."""


@dataclass(frozen=True)
class DirectSpec:
    """``ethercat:eth1``: the tool as EtherCAT master on a network card of its own."""

    nic: str

    interface = "ethercat"
    bitrate = 100_000_000

    @property
    def channel(self) -> str:
        return self.nic

    @classmethod
    def parse(cls, text: str) -> DirectSpec:
        match = _NIC_RE.match(text.strip())
        if not match:
            raise BusSpecError(Text(N_("'{text}' is not a network card: write ethercat:NIC, e.g. ethercat:eth1"),
                                     text=text))
        return cls(match["nic"])

    def __str__(self) -> str:
        return f"ethercat:{self.nic}"


@dataclass(frozen=True)
class SiiSlave:
    """A slave as SOEM's scan found it: its position, the station address it got, its identity from the SII."""

    position: int
    station: int
    name: str
    vendor_id: int
    product_code: int
    revision: int


def network_cards() -> list[str]:
    return sorted(path.name for path in NET_CLASS.iterdir()) if NET_CLASS.is_dir() else []


def may_use_raw_sockets() -> bool:
    """CAP_NET_RAW in the effective set (root has it unless a container or setpriv took it away)."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("CapEff:"):
                    return bool(int(line.split()[1], 16) >> CAP_NET_RAW & 1)
    except OSError:
        pass
    return False


def load_pysoem() -> ModuleType | None:
    try:
        return importlib.import_module("pysoem")
    except ImportError:
        return None


def refusal(spec: DirectSpec) -> Text | None:
    """Why a direct master on ``spec.nic`` cannot run here, in words (in the reader's language where shown); None if
    it could."""
    if load_pysoem() is None:
        return Text(N_("The direct EtherCAT master needs pysoem: install DriveBench with its extra ({install}), or "
                        "reach the slaves through a master's mailbox gateway (ethercat-mbg:HOST)."), install=INSTALL)
    if not may_use_raw_sockets():
        return Text(N_("The direct EtherCAT master sends raw Ethernet frames on {nic}: run DriveBench as root or give "
                        "its Python CAP_NET_RAW (setcap cap_net_raw+ep), or reach the slaves through a master's "
                        "mailbox gateway (ethercat-mbg:HOST)."), nic=spec.nic)
    cards = network_cards()
    if spec.nic not in cards:
        if not cards:
            return Text(N_("This computer has no network card '{nic}'; it has none (see ip link)."), nic=spec.nic)
        return Text(N_("This computer has no network card '{nic}'; it has {cards} (see ip link)."), nic=spec.nic,
                     cards=", ".join(cards))
    return None


def open_link(spec: DirectSpec, timeout_s: float) -> SoemLink:
    """pysoem's master on the card, or the reason in words why not (blocking: call it in a worker thread)."""
    why = refusal(spec)
    pysoem = load_pysoem()
    if why is not None or pysoem is None:
        raise TransportError(why or Text(N_("pysoem is missing ({install})"), install=INSTALL))
    return SoemLink(spec, pysoem, timeout_s=timeout_s)


class SoemLink:
    """One pysoem master on one card. ``pysoem`` is the module (a test may hand in a stand-in of its API)."""

    def __init__(self, spec: DirectSpec, pysoem: Any, *, timeout_s: float = 0.5) -> None:
        self.spec = spec
        self.pysoem = pysoem
        self.lock = threading.Lock()
        """Held around every mailbox, register and state call: the master does one at a time."""
        self.timeout_s = timeout_s
        self.on_emergency: EmergencyHandler | None = None
        self.slaves: list[Any] = []
        self.mapped = False
        """True once the slaves' process data is mapped (config_map): needed above Pre-Operational."""
        self.cyclic = threading.Event()
        """Set while a slave is Safe-Operational or higher: the cycle thread exchanges process data."""
        self._closed = threading.Event()
        self._cycle: threading.Thread | None = None
        self.master = pysoem.Master()
        try:
            self.master.open(spec.nic)
        except ConnectionError as exc:
            raise TransportError(Text(N_("pysoem could not open {nic} for raw EtherCAT frames: {reason}"),
                                       nic=spec.nic, reason=exc),
                                 hint=N_("Check that the card is up (ip link set dev NIC up) and that no other master "
                                         "uses it.")) from exc
        self.master.manual_state_change = 1  # the tool asks for every state itself (SOEM would go to Pre-Op/Safe-Op)
        self.master.always_release_gil = True  # the cycle thread runs while a transfer waits for its answer

    # --- scan ---------------------------------------------------------------------------------------------------
    def scan(self) -> list[SiiSlave]:
        """Enumerate the segment (every slave goes to Init); hold ``lock``."""
        self.cyclic.clear()
        self.mapped = False
        found = self.master.config_init()
        self.slaves = list(self.master.slaves or []) if found > 0 else []
        for slave in self.slaves:
            slave.add_emergency_callback(self._emergency)
        if self.slaves and self._cycle is None:
            self._cycle = threading.Thread(target=self._run_cycle, name=f"soem-{self.spec.nic}", daemon=True)
            self._cycle.start()
        return [SiiSlave(position, self.register(position, REG_STATION), slave.name, slave.man, slave.id, slave.rev)
                for position, slave in enumerate(self.slaves, start=1)]

    def _slave(self, position: int) -> Any:
        if not 1 <= position <= len(self.slaves):
            raise ProtocolError(Text(N_("No slave at position {position} on {nic}: scan the segment"),
                                      position=position, nic=self.spec.nic))
        return self.slaves[position - 1]

    # --- registers and states -----------------------------------------------------------------------------------
    def register(self, position: int, address: int) -> int:
        """A 16-bit ESC register of the slave (configured-address read, FPRD)."""
        try:
            data = self._slave(position)._fprd(address, 2, int(self.timeout_s * 1e6))
        except self.pysoem.WkcError as exc:
            raise ProtocolError(Text(N_("The slave at position {position} on {nic} did not answer the read of "
                                         "register {register}: lost from the segment (cable, power)?"),
                                      position=position, nic=self.spec.nic, register=f"0x{address:04X}")) from exc
        return int.from_bytes(data[:2], "little")

    def request_state(self, position: int, request: int, timeout_s: float) -> int:
        """Write AL control and wait up to ``timeout_s`` for the state; the state found then."""
        slave = self._slave(position)
        slave.state = request
        slave.write_state()
        return int(slave.state_check(request & 0x0F, int(timeout_s * 1e6)))

    def map_process_data(self) -> int:
        """Map every slave's PDOs into the master's process image (SOEM reads 0x1C12/0x1C13 and the mappings by CoE,
        so the slaves must be Pre-Operational); the image's size in bytes."""
        try:
            size = int(self.master.config_map())
        except self.pysoem.ConfigMapError as exc:
            reasons = Text.joined("; ", [self._error_text(error) for error in exc.error_list])
            raise ProtocolError(Text(N_("The process data of the slaves on {nic} could not be mapped: {reasons}"),
                                      nic=self.spec.nic, reasons=reasons)) from exc
        self.mapped = True
        return size

    # --- mailboxes ----------------------------------------------------------------------------------------------
    def sdo_read(self, position: int, index: int, subindex: int, timeout_s: float) -> bytes:
        self.master.sdo_read_timeout = int(timeout_s * 1e6)
        return bytes(self._sdo(position, index, subindex,
                               lambda slave: slave.sdo_read(index, subindex, SDO_BUFFER)))

    def sdo_write(self, position: int, index: int, subindex: int, data: bytes, timeout_s: float) -> None:
        self.master.sdo_write_timeout = int(timeout_s * 1e6)
        self._sdo(position, index, subindex, lambda slave: slave.sdo_write(index, subindex, bytes(data)))

    def _sdo(self, position: int, index: int, subindex: int, call: Callable[[Any], Any]) -> Any:
        slave = self._slave(position)
        errors = self.pysoem
        try:
            return call(slave)
        except errors.SdoError as exc:
            raise SdoAbortError(int(exc.abort_code), str(exc.desc), node=position, index=index,
                                subindex=subindex) from exc
        except errors.WkcError as exc:
            raise SdoTimeoutError(Text(N_("The slave at position {position} did not answer the SDO request for "
                                           "{object}"), position=position, object=f"0x{index:04X}sub{subindex}"),
                                  node=position, index=index, subindex=subindex) from exc
        except (errors.MailboxError, errors.PacketError) as exc:
            raise ProtocolError(Text(N_("Slave at position {position}, {object}: {reason}"), position=position,
                                      object=f"0x{index:04X}sub{subindex}", reason=self._error_text(exc))) from exc

    def _error_text(self, error: Exception) -> str:
        """One of pysoem's errors in words (its ``desc`` is SOEM's own English)."""
        if isinstance(error, self.pysoem.SdoError):
            return Text(N_("SDO abort {code} for {object} ({reason})"), code=f"0x{error.abort_code:08X}",
                         object=f"0x{error.index:04X}sub{error.subindex}", reason=error.desc)
        if isinstance(error, self.pysoem.MailboxError):
            return Text(N_("the slave refused the mailbox request: {reason} (mailbox error {code})"),
                         reason=error.desc, code=error.error_code)
        if isinstance(error, self.pysoem.PacketError):
            with contextlib.suppress(KeyError):
                return Text(N_("mailbox packet error: {reason}"), reason=error.desc)
            return Text(N_("mailbox packet error {code}"), code=error.error_code)
        return str(error)

    def _emergency(self, emergency: Any) -> None:
        if self.on_emergency is None:
            return
        data = bytes([emergency.b1]) + int(emergency.w1).to_bytes(2, "little") + int(emergency.w2).to_bytes(2, "little")
        self.on_emergency(int(emergency.slave_pos), int(emergency.error_code), int(emergency.error_reg), data,
                          time.time())

    def poll_mailboxes(self) -> None:
        """Read what the slaves left in their mailboxes (emergencies); hold ``lock``."""
        for slave in self.slaves:
            with contextlib.suppress(Exception):  # a slave without a mailbox (Init) or gone: the next scan says so
                slave.mbx_receive()

    # --- the cycle thread ---------------------------------------------------------------------------------------
    def _run_cycle(self) -> None:
        next_poll = time.monotonic()
        while not self._closed.is_set():
            if self.cyclic.is_set() and self.mapped:
                with contextlib.suppress(Exception):  # a lost frame is the slave's watchdog's business
                    self.master.send_processdata()
                    self.master.receive_processdata(int(CYCLE_S * 1e6))
            if time.monotonic() >= next_poll and self.lock.acquire(blocking=False):
                try:
                    self.poll_mailboxes()
                finally:
                    self.lock.release()
                next_poll = time.monotonic() + MAILBOX_POLL_S
            self._closed.wait(CYCLE_S if self.cyclic.is_set() else MAILBOX_POLL_S)

    @property
    def carrier_text(self) -> Text | None:
        """The card's link in words while it has none (cable unplugged), else None (worded when shown)."""
        try:
            carrier = (NET_CLASS / self.spec.nic / "carrier").read_text(encoding="ascii").strip()
        except OSError:
            return None  # down cards cannot be read; the next transfer says what is wrong
        if carrier == "1":
            return None
        return Text(N_("{nic} has no link: is the cable to the first slave plugged in?"), nic=self.spec.nic)

    def close(self) -> None:
        self._closed.set()
        if self._cycle is not None:
            self._cycle.join(timeout=2)
        with self.lock:
            self.master.close()
