"""Simulated EtherCAT slaves behind a simulated master's mailbox gateway (ETG.8200) on UDP.

A :class:`SimulatedSlave` is a :class:`SimulatedNode` (the object store, drive behaviour and faults the CAN drives
use, built from the same profile) behind a CoE mailbox instead of CAN: SDO and the SDO information service (its
object dictionary described from the store, :mod:`drivebench.simulator.coe_dictionary`) through the protocol's
:class:`CoeSdoServer`, emergencies as CoE emergency telegrams, and the EtherCAT state machine with the 8400 motec
EtherCAT manual's rules: mailbox only from Pre-Operational on (in Init the master cannot reach the mailbox: no
answer), PDO mapping 0x1600/0x1A00 and assignment 0x1C12/0x1C13 written only in Pre-Operational (else abort
0x08000022, "Due to the current device state, data cannot be transferred to the application or stored in the
application"), C13861 "Bus state" and C13879 "Bus error" following the state machine, AL status codes of §7.3.
The manual does not say how C13861 encodes the state: the simulated unit shows the AL status register's value (our
reading); C13879 bit 0 "General bus error" is set while a refused state change stands.

:class:`GatewayServer` is the master's side: a UDP socket on 127.0.0.1 forwarding mailbox telegrams to the slave whose
station address they name, and the master's own object dictionary at station address 0 (configured address list,
configuration and diagnosis objects per slave, see :mod:`drivebench.protocol.ethercat.esm`). Emergencies go to the
last peer that talked to the slave (a master forwards what it read from the slave's mailbox to the gateway client;
our reading).
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Mapping

from pydantic import BaseModel, ConfigDict, Field, field_validator

from drivebench.device.profiles import ethercat_section
from drivebench.device.profiles.profile import Profile
from drivebench.i18n import _
from drivebench.protocol.canopen.sdo_server import SdoAbort
from drivebench.protocol.datatypes import DataType, encode
from drivebench.protocol.ethercat import coe, esm
from drivebench.protocol.ethercat.coe_server import Abort, CoeSdoServer
from drivebench.simulator.coe_dictionary import StoreDictionary
from drivebench.simulator.node import Latency, LatencyText, SimulatedNode
from drivebench.simulator.ticker import DeadlineTicker
from drivebench.transport.ethercat_gateway import GatewayFormatError, GatewaySpec, gateway_frame, telegram_of

PREOP_ONLY = (0x1600, 0x1A00, 0x1C12, 0x1C13)
"""PDO mapping and assignment: written only in Pre-Operational (manual §8, ETG.1000.6)."""
ABORT_DEVICE_STATE = 0x08000022
BUS_STATE, BUS_ERROR = "C13861", "C13879"


class SimulatedSlave:
    def __init__(self, profile: Profile, station: int, position: int, *, name: str | None = None,
                 latency: Latency | None = None, values: Mapping[str, object] | None = None,
                 mailbox_size: int = 128) -> None:
        self.station = station
        self.position = position
        self.emergency_sink: Callable[[bytes], None] | None = None
        # The node id only resolves $NODEID defaults and the CAN identifiers nobody hears here.
        self.node = SimulatedNode(profile, min(position + 1, 127), self._on_can_frame, name=name, latency=latency,
                                  values=values)
        self.name = self.node.name
        self.store = self.node.store
        self.state = esm.EsmState.INIT
        self.states = (profile.ethercat or ethercat_section.DEFAULT).states
        self.error = False
        self.status_code = 0
        self._lock = threading.Lock()
        self._emergency_counter = 0
        self.server = CoeSdoServer(station, self._read, self._write, mailbox_size=mailbox_size,
                                   dictionary=StoreDictionary(self.store, PREOP_ONLY))
        self.store.add_write_check(self._check_state)

    # --- power and state machine ----------------------------------------------------------------------
    def power_on(self) -> None:
        self.node.power_on()
        self.request_state(esm.EsmState.PRE_OPERATIONAL)  # the master's start-up: Init -> Pre-Op

    def power_off(self) -> None:
        self.node.power_off()

    @property
    def al_status(self) -> int:
        return int(self.state) | (esm.ERROR_FLAG if self.error else 0)

    def request_state(self, target: int) -> int:
        """Carry out an AL control request; returns the AL status code (0: reached)."""
        with self._lock:
            refusal = esm.transition_refusal(self.state, target, self.states)
            if refusal is None:
                self.state = esm.EsmState(target)
                self.error = False
                self.status_code = 0
            else:
                self.error = True
                self.status_code = refusal
        self._mirror_state()
        return self.status_code

    def _mirror_state(self) -> None:
        for ref, value in ((BUS_STATE, self.al_status), (BUS_ERROR, 1 if self.error else 0)):
            with contextlib.suppress(Exception):  # a profile without the code simply has no display of it
                self.store.set_ref(ref, value)

    def _check_state(self, index: int, sub: int, raw: object) -> None:
        if index in PREOP_ONLY and self.state is not esm.EsmState.PRE_OPERATIONAL:
            raise SdoAbort(ABORT_DEVICE_STATE)

    # --- mailbox ---------------------------------------------------------------------------------------
    def mailbox(self, telegram: bytes) -> list[bytes]:
        """The answers to one mailbox telegram (several: the fragments of an SDO information response), or none
        (Init: no mailbox; Bootstrap: FoE only, no CoE)."""
        if self.state in (esm.EsmState.INIT, esm.EsmState.BOOTSTRAP):
            return []
        extra_ms = self.node.faults.faults.latency_ms
        delay = self.node.latency.sample() + (extra_ms or 0) / 1000
        if delay:
            time.sleep(delay)
        return self.server.respond(telegram)

    def _read(self, index: int, sub: int) -> bytes:
        try:
            return self.store.read(index, sub)
        except SdoAbort as exc:
            raise Abort(exc.code) from exc

    def _write(self, index: int, sub: int, data: bytes) -> None:
        try:
            self.store.write(index, sub, data)
        except SdoAbort as exc:
            raise Abort(exc.code) from exc

    def _on_can_frame(self, cob_id: int, data: bytes) -> None:
        """What the node would put on CAN: its emergencies become CoE emergencies, the rest has no CAN to go to."""
        if cob_id != self.node.emcy_cob_id() or self.emergency_sink is None or len(data) != 8:
            return
        self._emergency_counter = self._emergency_counter % 7 + 1
        self.emergency_sink(coe.coe_mailbox(self.station, coe.CoeService.EMERGENCY, bytes(data),
                                            self._emergency_counter))

    def raise_fault(self, code: int, register: int = 0x01, vendor: bytes = b"") -> None:
        self.node.raise_emcy(code, register, vendor)

    def tick(self, now: float) -> float | None:
        return self.node.tick(now)


class SimulatedMaster:
    """The master's object dictionary at station address 0 (see :mod:`drivebench.protocol.ethercat.esm`)."""

    def __init__(self, slaves: list[SimulatedSlave], *, diagnosis: bool = True) -> None:
        self.slaves = slaves
        self.diagnosis = diagnosis
        """False: a master without the diagnosis objects 0xA000 + n (their reads and writes abort 0x06020000)."""
        self.server = CoeSdoServer(esm.MASTER_STATION, self._read, self._write)

    def _slave(self, index: int, base: int) -> SimulatedSlave:
        number = index - base
        if not 0 <= number < len(self.slaves):
            raise Abort(0x06020000)
        return self.slaves[number]

    def _read(self, index: int, sub: int) -> bytes:
        if index == esm.ADDRESS_LIST:
            if sub == 0:
                return bytes([len(self.slaves)])
            if 1 <= sub <= len(self.slaves):
                return self.slaves[sub - 1].station.to_bytes(2, "little")
            raise Abort(0x06090011)
        if esm.CONFIGURATION_BASE <= index < esm.CONFIGURATION_BASE + esm.MAX_SLAVES:
            return self._configuration(self._slave(index, esm.CONFIGURATION_BASE), sub)
        if self.diagnosis and esm.DIAGNOSIS_BASE <= index < esm.DIAGNOSIS_BASE + esm.MAX_SLAVES:
            slave = self._slave(index, esm.DIAGNOSIS_BASE)
            values = {0: bytes([3]), esm.SUB_AL_STATUS: slave.al_status.to_bytes(2, "little"),
                      esm.SUB_AL_CONTROL: int(slave.state).to_bytes(2, "little"),
                      esm.SUB_AL_STATUS_CODE: slave.status_code.to_bytes(2, "little")}
            if sub not in values:
                raise Abort(0x06090011)
            return values[sub]
        raise Abort(0x06020000)

    @staticmethod
    def _configuration(slave: SimulatedSlave, sub: int) -> bytes:
        identity = slave.node.profile.identity
        vendor = int(identity.vendor_id or 0)
        values: dict[int, bytes] = {
            0: bytes([esm.SUB_SERIAL]),
            esm.SUB_STATION: slave.station.to_bytes(2, "little"),
            esm.SUB_NAME: encode(DataType.VISIBLE_STRING, slave.name),
            esm.SUB_VENDOR: vendor.to_bytes(4, "little"),
            esm.SUB_PRODUCT: int(identity.product_code or 0).to_bytes(4, "little"),
            esm.SUB_REVISION: bytes(4), esm.SUB_SERIAL: (slave.position + 1).to_bytes(4, "little"),
        }
        if sub not in values:
            raise Abort(0x06090011)
        return values[sub]

    def _write(self, index: int, sub: int, data: bytes) -> None:
        if not self.diagnosis and esm.DIAGNOSIS_BASE <= index < esm.DIAGNOSIS_BASE + esm.MAX_SLAVES:
            raise Abort(0x06020000)
        if not esm.DIAGNOSIS_BASE <= index < esm.DIAGNOSIS_BASE + esm.MAX_SLAVES:
            raise Abort(0x06010002 if index == esm.ADDRESS_LIST or index >= esm.CONFIGURATION_BASE else 0x06020000)
        slave = self._slave(index, esm.DIAGNOSIS_BASE)
        if sub != esm.SUB_AL_CONTROL:
            raise Abort(0x06010002 if sub in (0, esm.SUB_AL_STATUS, esm.SUB_AL_STATUS_CODE) else 0x06090011)
        if len(data) != 2:
            raise Abort(0x06070010)
        target = int.from_bytes(data, "little") & 0x0F
        # A master takes a slave up one state at a time (Pre-Op -> Safe-Op -> Op), and to and from Bootstrap through
        # Init where the slave has it; the slave refuses what it must.
        bootstrap = esm.EsmState.BOOTSTRAP
        if bootstrap in slave.states and bootstrap in (target, slave.state):
            if target not in (slave.state, esm.EsmState.INIT) and slave.request_state(esm.EsmState.INIT):
                return
            if target == bootstrap:
                slave.request_state(target)
                return
        steps = [esm.EsmState.PRE_OPERATIONAL, esm.EsmState.SAFE_OPERATIONAL, esm.EsmState.OPERATIONAL]
        for step in steps:
            if step.value < target and step.value > slave.state.value and slave.request_state(step):
                return
        slave.request_state(target)


class GatewayServer:
    """A master's mailbox gateway on UDP: one thread receives, each slave answers in its own worker thread."""

    def __init__(self, slaves: list[SimulatedSlave], *, host: str = "127.0.0.1", port: int = 0,
                 diagnosis: bool = True) -> None:
        self.slaves = {slave.station: slave for slave in slaves}
        self.master = SimulatedMaster(slaves, diagnosis=diagnosis)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, port))
        self.host, self.port = self._sock.getsockname()[:2]
        self._peers: dict[int, tuple[str, int]] = {}
        self._closed = threading.Event()
        self._threads: list[threading.Thread] = []
        self._slave_locks = {station: threading.Lock() for station in self.slaves}
        self.malformed = 0
        self._ticker = DeadlineTicker(self.slaves.values, "sim-mbg-tick")
        for slave in slaves:
            slave.emergency_sink = self._emergency_sender(slave.station)
            slave.node.wake = self._ticker.wake

    @property
    def spec(self) -> str:
        return f"ethercat-mbg:{self.host}:{self.port}"

    def start(self) -> GatewayServer:
        for slave in self.slaves.values():
            slave.power_on()
        thread = threading.Thread(target=self._receive, name="sim-mbg-rx", daemon=True)
        thread.start()
        self._threads.append(thread)
        self._ticker.start()
        return self

    def stop(self) -> None:
        self._closed.set()
        self._ticker.stop()
        self._wake_receiver()
        for thread in self._threads:
            thread.join(timeout=2)
        with contextlib.suppress(OSError):
            self._sock.close()
        for slave in self.slaves.values():
            slave.power_off()

    def _wake_receiver(self) -> None:
        """An empty datagram ends the receiver's wait (closing a UDP socket does not wake a thread in recvfrom on
        Linux: the thread stayed blocked for the life of the process)."""
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as waker:
            waker.sendto(b"", (host, self.port))

    def _emergency_sender(self, station: int) -> Callable[[bytes], None]:
        def send(telegram: bytes) -> None:
            peer = self._peers.get(station)
            if peer is not None and not self._closed.is_set():
                with contextlib.suppress(OSError):
                    self._sock.sendto(gateway_frame(telegram), peer)
        return send

    def _receive(self) -> None:
        while not self._closed.is_set():
            try:
                datagram, peer = self._sock.recvfrom(1500)
            except OSError:
                return
            try:
                telegram = telegram_of(datagram)
                station = coe.Mailbox.decode(telegram).address
            except (GatewayFormatError, coe.MailboxFormatError):
                self.malformed += 1
                continue
            self._peers[station] = peer
            threading.Thread(target=self._answer, args=(station, telegram, peer), daemon=True,
                             name=f"sim-mbg-{station}").start()

    def _answer(self, station: int, telegram: bytes, peer: tuple[str, int]) -> None:
        if station == esm.MASTER_STATION:
            answers = self.master.server.respond(telegram)
        else:
            slave = self.slaves.get(station)
            if slave is None:
                return  # no slave has this station address: the master has nowhere to deliver it
            with self._slave_locks[station]:
                answers = slave.mailbox(telegram)
        for answer in answers:
            if self._closed.is_set():
                return
            with contextlib.suppress(OSError):
                self._sock.sendto(gateway_frame(answer), peer)


class LineSlave(BaseModel):
    model_config = ConfigDict(extra="forbid")

    station: int = Field(ge=1, le=0xFFFF, description="configured station address")
    profile: str
    name: str | None = None
    latency: LatencyText = "0ms"
    values: dict[str, int | float | str] = Field(default_factory=dict)


class EthercatLine(BaseModel):
    """A plant file's ``ethercat`` section: slaves behind a simulated master's mailbox gateway.

    ``gateway`` is where it listens (``ethercat-mbg:127.0.0.1:0`` takes a free port)."""

    model_config = ConfigDict(extra="forbid")

    name: str = "EtherCAT line"
    gateway: str = "ethercat-mbg:127.0.0.1:0"
    slaves: list[LineSlave]

    @field_validator("gateway")
    @classmethod
    def _check_gateway(cls, value: str) -> str:
        GatewaySpec.parse(value.removesuffix(":0"))  # port 0: any free one
        return value

    @field_validator("slaves")
    @classmethod
    def _unique_stations(cls, slaves: list[LineSlave]) -> list[LineSlave]:
        stations = [slave.station for slave in slaves]
        if len(set(stations)) != len(stations):
            raise ValueError(_("two slaves have the same station address"))
        return slaves

    def start(self, profiles: Callable[[str], Profile], *, port: int | None = None,
              latency: str | None = None) -> GatewayServer:
        where = self.gateway.removeprefix("ethercat-mbg:")
        host, _, configured = where.rpartition(":") if ":" in where else (where, "", "0")
        slaves = [SimulatedSlave(profiles(slave.profile), slave.station, position, name=slave.name,
                                 latency=Latency.parse(latency if latency is not None else slave.latency),
                                 values=slave.values)
                  for position, slave in enumerate(self.slaves)]
        return GatewayServer(slaves, host=host or "127.0.0.1",
                             port=int(configured or 0) if port is None else port).start()
