"""The tool as EtherCAT master on a network card (``ethercat:eth1``, pysoem): the slaves SOEM finds, their states
and their mailboxes, seen the way a session sees a CAN network (:class:`EthercatNetwork`).

* Scan: SOEM enumerates the segment (every slave goes to Init) and gives the slave at position p the configured
  station address 0x1000 + p (read back from register 0x0010); name, vendor id, product code and revision come from
  the slave's SII. Session nodes are numbered by position (1 = next to the master). Then every slave is asked for
  Pre-Operational, where its mailbox (CoE SDO) works. A slave above Pre-Operational is never re-scanned.
* States: the tool writes AL control itself (with the error acknowledge bit while the slave shows an error) and reads
  the AL status register (0x0130) and the AL status code (0x0134); the texts are the manual's (:mod:`esm`).
* Safe-Operational and Operational need the process data mapped: before the first step above Pre-Operational SOEM
  maps every slave's PDOs (as assigned in 0x1C12/0x1C13, read by CoE), and the link's cycle thread then exchanges
  process data every 4 ms with **outputs of zero**: the tool never moves a drive through process data; drive
  control stays the Lenze codes by CoE, behind the safety guard's confirmation and keep-alive.
* CoE SDO: pysoem's sdo_read/sdo_write (expedited, normal, segmented) with the errors of CAN SDO, retried on silence
  like the mailbox gateway's client; counted per slave for the monitor.
"""

from __future__ import annotations

import threading

from drivebench.errors import ProtocolError, SdoAbortError, SdoTimeoutError
from drivebench.i18n import N_, Text
from drivebench.protocol.ethercat import esm
from drivebench.protocol.ethercat.network import NOT_CHANGED, EthercatNetwork, SlaveInfo
from drivebench.protocol.ethercat.segment import EmergencyListener, MailboxCounters
from drivebench.transport.ethercat_soem import REG_AL_STATUS, REG_AL_STATUS_CODE, DirectSpec, SiiSlave, SoemLink

STATE_TIMEOUT_S = 5.0
"""How long a slave may take to reach a requested state (Init -> Pre-Op includes its mailbox set-up)."""
ACKNOWLEDGE = 0x10
"""AL control bit 4: acknowledge the error the AL status shows."""
UPWARDS: list[esm.EsmState] = [esm.EsmState.INIT, esm.EsmState.PRE_OPERATIONAL, esm.EsmState.SAFE_OPERATIONAL,
                               esm.EsmState.OPERATIONAL]
DIRECT_HINT = N_("Check the cable from this card to the first slave's IN port, the slaves' power, and that the slave "
                 "is at least Pre-Operational (the Plant page shows its state).")


class SoemSdo:
    """One slave's SDO client on the direct master (:class:`~drivebench.protocol.ethercat.network.SdoTransfers`)."""

    def __init__(self, link: SoemLink, position: int, counters: MailboxCounters, *, timeout_s: float,
                 retries: int) -> None:
        self.link = link
        self.position = position
        self.counters = counters
        self.timeout_s = timeout_s
        self.retries = retries

    def _counted(self, index: int, subindex: int, work: str, data: bytes = b"") -> bytes:
        for attempt in range(self.retries + 1):
            self.counters.requests += 1
            try:
                if work == "upload":
                    answer = self.link.sdo_read(self.position, index, subindex, self.timeout_s)
                else:
                    self.link.sdo_write(self.position, index, subindex, data, self.timeout_s)
                    answer = b""
            except SdoAbortError:
                self.counters.responses += 1
                self.counters.aborts += 1
                raise
            except SdoTimeoutError:
                self.counters.timeouts += 1
                if attempt == self.retries:
                    raise
                continue
            except ProtocolError:  # a mailbox error reply is an answer too
                self.counters.responses += 1
                raise
            self.counters.responses += 1
            return answer
        raise AssertionError("unreachable")

    def upload(self, index: int, subindex: int) -> bytes:
        return self._counted(index, subindex, "upload")

    def download(self, index: int, subindex: int, data: bytes) -> None:
        self._counted(index, subindex, "download", data)


class SoemMailboxes:
    """The slaves' mailboxes on the direct master by station address (one lock: the master's)."""

    def __init__(self, link: SoemLink, *, timeout_s: float, retries: int) -> None:
        self.link = link
        self.timeout_s = timeout_s
        self.retries = retries
        self.positions: dict[int, int] = {}
        """Station address -> position, from the last scan."""
        self._counters: dict[int, MailboxCounters] = {}
        self._clients: dict[int, SoemSdo] = {}
        self._listeners: list[EmergencyListener] = []
        link.on_emergency = self._on_emergency

    def lock(self, station: int) -> threading.Lock:
        return self.link.lock

    def counters(self, station: int) -> MailboxCounters:
        return self._counters.setdefault(station, MailboxCounters())

    def position(self, station: int) -> int:
        position = self.positions.get(station)
        if position is None:
            raise ProtocolError(Text(N_("No slave has station address {station} on {nic}: scan the segment"),
                                      station=station, nic=self.link.spec.nic))
        return position

    def sdo(self, station: int) -> SoemSdo:
        client = self._clients.get(station)
        if client is None or client.position != self.position(station):
            client = self._clients[station] = SoemSdo(self.link, self.position(station), self.counters(station),
                                                      timeout_s=self.timeout_s, retries=self.retries)
        return client

    def add_emergency_listener(self, listener: EmergencyListener) -> None:
        self._listeners.append(listener)

    def _on_emergency(self, position: int, code: int, register: int, data: bytes, timestamp: float) -> None:
        station = next((known for known, at in self.positions.items() if at == position), None)
        if station is None:
            return
        self.counters(station).emergencies += 1
        for listener in self._listeners:
            listener(station, code, register, data, timestamp)

    def close(self) -> None:
        self.link.close()


class DirectNetwork(EthercatNetwork):
    silence_hint = DIRECT_HINT

    def __init__(self, spec: DirectSpec, link: SoemLink, *, sdo_timeout_s: float = 0.5, sdo_retries: int = 1) -> None:
        self.link = link
        self.mailboxes = SoemMailboxes(link, timeout_s=sdo_timeout_s, retries=sdo_retries)
        super().__init__(spec, self.mailboxes, sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)
        self.nic = spec.nic
        self.found: dict[int, SiiSlave] = {}
        self.statuses: dict[int, int] = {}
        """Position -> AL status last read."""

    def _position(self, node_id: int) -> int:
        return self.mailboxes.position(self.station(node_id))

    # --- scan -------------------------------------------------------------------------------------------------
    def scan(self, timeout_s: float = 0.5, node_ids: range | None = None) -> list[int]:
        """Enumerate the segment, then ask every slave for Pre-Operational (the list comes back in any case)."""
        with self.link.lock:
            for node_id in sorted(self.stations):
                try:
                    status = self._read_al(node_id)[0]
                except ProtocolError:
                    continue  # gone from the segment: nothing of it runs
                if status & 0x0F > esm.EsmState.PRE_OPERATIONAL:
                    raise ProtocolError(Text(N_("Slave {node} is {state}: take the slaves to Pre-Operational "
                                                 "before scanning again (a scan takes every slave to Init)."),
                                              node=node_id, state=esm.al_status_text(status)))
            found = self.link.scan()
        if not found:
            raise ProtocolError(Text(N_("No EtherCAT slave answered on {nic}: check the cable from this card to "
                                         "the first slave's IN port, the slaves' power, and that no other master "
                                         "uses the card."), nic=self.nic))
        self.found = {slave.position: slave for slave in found}
        self.statuses.clear()
        self.stations = {slave.position: slave.station for slave in found}
        self.mailboxes.positions = {slave.station: slave.position for slave in found}
        self.nodes.clear()
        for position in self.found:
            try:  # a slave that stays in Init says so in its state text; the others' list is still good
                self._change(position, esm.EsmState.PRE_OPERATIONAL)
            except ProtocolError:
                continue
        return sorted(self.found)

    def slave(self, node_id: int) -> SlaveInfo:
        self.station(node_id)
        sii = self.found[node_id]
        info = SlaveInfo(node_id, sii.station, sii.name, sii.vendor_id, sii.product_code, sii.revision)
        with self.link.lock:
            info.al_status, info.al_status_code = self._read_al(node_id)
        return info

    # --- the state machine ------------------------------------------------------------------------------------
    def _read_al(self, node_id: int) -> tuple[int, int]:
        position = self._position(node_id)
        status = self.link.register(position, REG_AL_STATUS)
        code = self.link.register(position, REG_AL_STATUS_CODE)
        self.statuses[position] = status
        return status, code

    def al_state(self, node_id: int) -> tuple[int, int]:
        with self.link.lock:
            return self._read_al(node_id)

    def _change(self, node_id: int, state: esm.EsmState) -> tuple[int, int]:
        """Request ``state`` of one slave and wait for it; the AL status and code then. Hold the link's lock."""
        status = self._read_al(node_id)[0]
        if state > esm.EsmState.PRE_OPERATIONAL and not self.link.mapped:
            self.link.map_process_data()
        request = int(state) | (ACKNOWLEDGE if status & esm.ERROR_FLAG else 0)
        self.link.request_state(self._position(node_id), request, STATE_TIMEOUT_S)
        status, code = self._read_al(node_id)
        self._update_cycle()
        if status & esm.ERROR_FLAG or status & 0x0F != state:
            raise ProtocolError(Text(NOT_CHANGED, node=node_id, station=self.station(node_id), state=state.label,
                                      reason=esm.al_status_text(status, code)))
        return status, code

    def _update_cycle(self) -> None:
        """Process data flows while a slave is Safe-Operational or higher; all back at Pre-Op or lower: mapped anew
        next time (the PDO mapping may change in Pre-Operational)."""
        above = any(status & 0x0F >= esm.EsmState.SAFE_OPERATIONAL for status in self.statuses.values())
        if above:
            self.link.cyclic.set()
        else:
            self.link.cyclic.clear()
            self.link.mapped = False

    def request_state(self, node_id: int, state: esm.EsmState) -> SlaveInfo:
        """Take one slave to ``state``, upwards one state at a time as a master does (a slave refuses a jump)."""
        if state is esm.EsmState.BOOTSTRAP:
            raise ProtocolError(Text(N_("The tool does not take slaves to Bootstrap (firmware download is not "
                                         "offered)")))
        with self.link.lock:
            current = self._read_al(node_id)[0] & 0x0F
            steps: list[esm.EsmState] = [state]
            if current in UPWARDS and UPWARDS.index(state) > UPWARDS.index(esm.EsmState(current)):
                steps = UPWARDS[UPWARDS.index(esm.EsmState(current)) + 1:UPWARDS.index(state) + 1]
            for step in steps:
                self._change(node_id, step)
        return self.slave(node_id)

    # --- silence ----------------------------------------------------------------------------------------------
    def silence_text(self, station: int, index: int, sub: int) -> Text:
        return Text(N_("Slave at station {station} on {nic} did not answer the mailbox request for {object} within "
                        "{seconds} s: not in Pre-Operational or higher, not on the segment any more, or slow"),
                     station=station, nic=self.nic, object=f"0x{index:04X}sub{sub}", seconds=f"{self.sdo_timeout_s:g}")

    @property
    def link_text(self) -> Text | None:
        return self.link.carrier_text
