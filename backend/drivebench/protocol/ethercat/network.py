"""An EtherCAT segment, seen the way a session sees a CAN network.

:class:`EthercatNetwork` offers what the services use of :class:`~drivebench.protocol.canopen.network.CanopenNetwork`:
``node(node_id)`` gives an SDO client with the same methods and the same errors as a CAN node's
(:class:`CoeNodeClient`), ``emcy`` keeps the slaves' CoE emergencies as the EMCY monitor keeps CAN's, ``scan`` finds
the slaves. What CAN has and EtherCAT has not (NMT, heartbeat, node guarding, frames by COB-ID) it does not offer:
its :attr:`~EthercatNetwork.capabilities` say so, and a service that needs frames is refused in words
(:func:`~drivebench.protocol.canopen.network.frames_of`).
How the slaves are reached is the subclass's: :class:`GatewayNetwork` through a running master's mailbox gateway,
:class:`~drivebench.protocol.ethercat.master.DirectNetwork` as the master itself on a network card (pysoem).

A session numbers its nodes 1, 2, ... in the order of the master's configured address list (the "position"; the
tool's pages and API address nodes by these numbers); every mailbox telegram is addressed by the slave's configured
station address, which the slave list shows next to it.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol, TypeVar, cast

from drivebench.errors import ProtocolError, SdoAbortError, SdoTimeoutError
from drivebench.i18n import N_, Text, _
from drivebench.protocol.abort_codes import abort_text
from drivebench.protocol.emcy import EmcyEvent, EmcyMonitor
from drivebench.protocol.ethercat import esm
from drivebench.protocol.ethercat.coe_sdo import SERVICE_NOT_SUPPORTED, CoeSdoClient, MailboxRefused
from drivebench.protocol.ethercat.segment import EmergencyListener, EthercatSegment, MailboxCounters
from drivebench.protocol.fieldbus import ETHERCAT, EventLoopTransfers, Fieldbus
from drivebench.transport.ethercat_gateway import GatewaySpec
from drivebench.transport.ethercat_soem import DirectSpec

T = TypeVar("T")
GATEWAY_HINT = N_("Check that the master runs with its mailbox gateway on, that the slave is in the master's "
                  "configuration and at least Pre-Operational.")
NOT_CHANGED = N_("Slave {node} (station {station}) did not change to {state}: {reason}")
GATEWAY_SILENT = N_("Mailbox gateway {bus}: {reason}")


@dataclass
class MailboxChannel:
    """The slave's one mailbox, as an SDO channel (a CAN node may have two)."""

    number: int
    lock: threading.Lock


@dataclass
class SlaveInfo:
    node_id: int
    station: int
    name: str = ""
    vendor_id: int | None = None
    product_code: int | None = None
    revision: int | None = None
    al_status: int | None = None
    al_status_code: int = 0

    @property
    def state_text(self) -> str:
        if self.al_status is None:
            return N_("Unknown")  # a state word: a page shows _(state)
        return esm.al_status_text(self.al_status, self.al_status_code)


class SdoTransfers(Protocol):
    """A slave's SDO client: upload/download raising the errors of CAN SDO."""

    timeout_s: float
    retries: int

    def upload(self, index: int, subindex: int) -> bytes: ...

    def download(self, index: int, subindex: int, data: bytes) -> None: ...


class SlaveMailboxes(Protocol):
    """The slaves' mailboxes by station address: what :class:`CoeNodeClient` and the monitor use of a segment."""

    def lock(self, station: int) -> threading.Lock: ...

    def sdo(self, station: int) -> SdoTransfers: ...

    def counters(self, station: int) -> MailboxCounters: ...

    def add_emergency_listener(self, listener: EmergencyListener) -> None: ...

    def close(self) -> None: ...


class CoeNodeClient(EventLoopTransfers):
    """SDO access to one slave through its mailbox: the methods and errors of a CAN node's client."""

    def __init__(self, network: EthercatNetwork, node_id: int, station: int,
                 abort_texts: Mapping[int, str] | None = None) -> None:
        self.network = network
        self.node_id = node_id
        self.station = station
        self.abort_texts: dict[int, str] = dict(abort_texts or {})
        """The device manual's abort texts (its profile's ``abort_texts``)."""
        self.channels = [MailboxChannel(1, network.segment.lock(station))]

    fast_path: None = None
    """No on-loop reads: a mailbox exchange runs in a worker thread."""
    sdo_servers: None = None
    """One mailbox per slave: no SDO channel to add."""
    domain_download: None = None
    """No CANopen block transfer through the mailbox (program download over EtherCAT is FoE, not built)."""

    @property
    def sdo_information(self) -> CoeNodeClient:
        """The client that asks the slave's SDO information service (:meth:`information`: its object list)."""
        return self

    def configure(self, timeout_s: float, retries: int) -> None:
        client = self.network.segment.sdo(self.station)
        client.timeout_s, client.retries = timeout_s, retries

    def add_channel(self, rx_cobid: int, tx_cobid: int) -> MailboxChannel:
        raise ProtocolError(Text(N_("Slave {node} (station {station}) has one mailbox; EtherCAT has no CAN "
                                     "identifiers for a second SDO channel"), node=self.node_id, station=self.station))

    def _in_mailbox(self, work: Callable[[SdoTransfers], T], index: int, sub: int, silence: str = "") -> T:
        """``work(client)`` while holding the slave's mailbox, with the profile's abort texts and the silence of
        the gateway or slave in words."""
        client = self.network.segment.sdo(self.station)
        with self.channels[0].lock:
            try:
                return work(client)
            except SdoAbortError as exc:
                raise SdoAbortError(exc.abort_code, abort_text(exc.abort_code, self.abort_texts), node=self.node_id,
                                    index=exc.index, subindex=exc.subindex) from exc
            except SdoTimeoutError as exc:
                if type(exc) is not SdoTimeoutError:  # a stalled segmented transfer says so already
                    raise
                said = Text.joined("", [self.network.silence_text(self.station, index, sub), silence])
                raise SdoTimeoutError(said, node=self.node_id, index=index, subindex=sub,
                                      hint=self.network.silence_hint) from exc

    def _transfer(self, index: int, sub: int, block: bool, work: str, data: bytes = b"") -> bytes:
        if block:
            raise ProtocolError(Text(N_("CoE has no SDO block transfer; read or write it normally (segmented)")))
        if work == "upload":
            return self._in_mailbox(lambda client: client.upload(index, sub), index, sub)
        self._in_mailbox(lambda client: client.download(index, sub, data), index, sub)
        return b""

    def information(self, ask: Callable[[CoeSdoClient], T], index: int = 0, sub: int = 0) -> T:
        """One SDO information exchange (``ask(client)``, blocking) with the errors of an SDO transfer; a slave
        without the service says so in words."""
        def on_coe(client: SdoTransfers) -> T:
            if not isinstance(client, CoeSdoClient):
                raise ProtocolError(Text(N_("Slave {node} (station {station}): the SDO information service is read "
                                             "through a mailbox gateway; the direct master does not ask it yet"),
                                          node=self.node_id, station=self.station))
            return ask(client)

        try:
            return self._in_mailbox(on_coe, index, sub, Text(N_(" (a slave without the SDO information service "
                                                                 "may not answer at all)")))
        except MailboxRefused as exc:
            if exc.code != SERVICE_NOT_SUPPORTED:
                raise
            raise ProtocolError(Text(N_("Slave {node} (station {station}) does not offer the SDO information "
                                         "service (its mailbox answered: the service is not supported)"),
                                      node=self.node_id, station=self.station)) from exc

    # ``urgent``: the mailbox lock is the segment's (shared with the master's own exchanges); it has no stop-first
    # queue yet, so a stop waits its turn there like any transfer
    def upload(self, index: int, sub: int, *, block: bool = False, channel: int | None = None,
               urgent: bool = False) -> bytes:
        return self._transfer(index, sub, block, "upload")

    def download(self, index: int, sub: int, data: bytes, *, block: bool = False,
                 channel: int | None = None, urgent: bool = False) -> None:
        self._transfer(index, sub, block, "download", data)

    def stop_first(self) -> contextlib.AbstractContextManager[None]:
        return contextlib.nullcontext()


class EthercatNetwork:
    """What every EtherCAT segment offers a session; the subclass opens ``segment`` and says how the slaves are
    found (scan), what state they are in and how to change it, and what a silence means."""

    capabilities = ETHERCAT
    silence_hint = GATEWAY_HINT
    """What to check when a slave does not answer its mailbox."""

    def __init__(self, spec: GatewaySpec | DirectSpec, segment: SlaveMailboxes, *, sdo_timeout_s: float = 0.5,
                 sdo_retries: int = 1) -> None:
        self.spec = spec
        self.sdo_timeout_s = sdo_timeout_s
        self.sdo_retries = sdo_retries
        self.segment = segment
        self.emcy = EmcyMonitor()
        self.nodes: dict[int, CoeNodeClient] = {}
        self.stations: dict[int, int] = {}
        """Session node number -> configured station address."""
        self.segment.add_emergency_listener(self._on_emergency)

    # --- nodes and slaves -----------------------------------------------------------------------------------
    def station(self, node_id: int) -> int:
        station = self.stations.get(node_id)
        if station is None:
            raise ProtocolError(Text(N_("Slave {node} is not in the master's list of {bus}: scan the segment"),
                                      node=node_id, bus=self.spec))
        return station

    def node(self, node_id: int, abort_texts: Mapping[int, str] | None = None) -> CoeNodeClient:
        """The slave's client; ``abort_texts`` (the profile's, when the caller knows it) replaces the client's."""
        client = self.nodes.get(node_id)
        if client is None:
            client = self.nodes[node_id] = CoeNodeClient(self, node_id, self.station(node_id), abort_texts)
        elif abort_texts is not None and abort_texts != client.abort_texts:
            client.abort_texts.clear()
            client.abort_texts.update(abort_texts)
        return client

    def sdo_label(self, node_id: int) -> str:
        """How the slave's SDOs travel, for the Parameters tab (in the reader's language): its mailbox, station address
        and gateway."""
        station = self.stations.get(node_id)
        if station is None:
            return _("CoE mailbox (not in the master's list, gateway {bus})").format(bus=self.spec)
        return _("CoE mailbox (station {station}, gateway {bus})").format(station=station, bus=self.spec)

    def counters(self, node_id: int) -> MailboxCounters:
        return self.segment.counters(self.station(node_id))

    def scan(self, timeout_s: float = 0.5, node_ids: range | None = None) -> list[int]:
        raise NotImplementedError

    def slave(self, node_id: int) -> SlaveInfo:
        raise NotImplementedError

    def al_state(self, node_id: int) -> tuple[int, int]:
        raise NotImplementedError

    def request_state(self, node_id: int, state: esm.EsmState) -> SlaveInfo:
        raise NotImplementedError

    def silence_text(self, station: int, index: int, sub: int) -> Text:
        raise NotImplementedError

    @property
    def link_text(self) -> Text | None:
        """The link to the segment in a sentence while it is lost, else None (worded when shown)."""
        raise NotImplementedError

    def _on_emergency(self, station: int, code: int, register: int, data: bytes, timestamp: float) -> None:
        """A CoE emergency, kept as CAN's are (CiA 301 code, error register, five bytes)."""
        node_id = next((number for number, known in self.stations.items() if known == station), None)
        if node_id is None or node_id > 127:
            return
        manufacturer = bytes(data[:5]).ljust(5, b"\0")
        self.emcy.record(EmcyEvent(node_id, code, register, manufacturer, timestamp or time.time()))

    def close(self) -> None:
        self.segment.close()


def master_of(network: Fieldbus[object]) -> EthercatNetwork | None:
    """The segment's master behind a session's fieldbus (slave list, AL states, mailbox counters), or None on a bus
    without one (CAN)."""
    return cast(EthercatNetwork, network) if network.capabilities.esm else None


class GatewayNetwork(EthercatNetwork):
    """The slaves behind a running master's mailbox gateway (ETG.8200, ``ethercat-mbg:HOST[:PORT]``)."""

    def __init__(self, spec: GatewaySpec, *, sdo_timeout_s: float = 0.5, sdo_retries: int = 1) -> None:
        self.gateway = EthercatSegment(spec, timeout_s=sdo_timeout_s, retries=sdo_retries)
        super().__init__(spec, self.gateway, sdo_timeout_s=sdo_timeout_s, sdo_retries=sdo_retries)

    def _master(self, index: int, sub: int) -> bytes:
        with self.gateway.lock(esm.MASTER_STATION):
            try:
                return self.gateway.sdo(esm.MASTER_STATION).upload(index, sub)
            except SdoTimeoutError as exc:
                raise SdoTimeoutError(Text(N_("The master behind {bus} did not answer: {reason}"), bus=self.spec,
                                            reason=self._silence()), node=0, index=index, subindex=sub) from exc

    def scan(self, timeout_s: float = 0.5, node_ids: range | None = None) -> list[int]:
        """The slaves in the master's configured address list (0xF020), numbered 1, 2, ... in its order."""
        count = self._master(esm.ADDRESS_LIST, 0)[0]
        self.stations = {number: int.from_bytes(self._master(esm.ADDRESS_LIST, number)[:2], "little")
                         for number in range(1, count + 1)}
        return sorted(self.stations)

    def slave(self, node_id: int) -> SlaveInfo:
        """The master's configuration and diagnosis objects of one slave."""
        station = self.station(node_id)
        configuration, diagnosis = esm.CONFIGURATION_BASE + node_id - 1, esm.DIAGNOSIS_BASE + node_id - 1
        info = SlaveInfo(node_id, station)
        info.name = self._master(configuration, esm.SUB_NAME).decode("utf-8", "replace").rstrip("\0")
        info.vendor_id = int.from_bytes(self._master(configuration, esm.SUB_VENDOR), "little")
        info.product_code = int.from_bytes(self._master(configuration, esm.SUB_PRODUCT), "little")
        try:
            info.al_status = int.from_bytes(self._master(diagnosis, esm.SUB_AL_STATUS), "little")
            info.al_status_code = int.from_bytes(self._master(diagnosis, esm.SUB_AL_STATUS_CODE), "little")
        except SdoAbortError:  # a master without the diagnosis object: AL state unknown, the slave still listed
            info.al_status, info.al_status_code = None, 0
        return info

    def al_state(self, node_id: int) -> tuple[int, int]:
        """The slave's AL status and last AL status code, as the master reports them now."""
        diagnosis = esm.DIAGNOSIS_BASE + node_id - 1
        self.station(node_id)
        return (int.from_bytes(self._master(diagnosis, esm.SUB_AL_STATUS), "little"),
                int.from_bytes(self._master(diagnosis, esm.SUB_AL_STATUS_CODE), "little"))

    def request_state(self, node_id: int, state: esm.EsmState) -> SlaveInfo:
        """Ask the master to take one slave to ``state`` (AL control); refused changes raise in words."""
        diagnosis = esm.DIAGNOSIS_BASE + node_id - 1
        self.station(node_id)
        with self.gateway.lock(esm.MASTER_STATION):
            try:
                self.gateway.sdo(esm.MASTER_STATION).download(diagnosis, esm.SUB_AL_CONTROL,
                                                              int(state).to_bytes(2, "little"))
            except SdoAbortError as exc:
                raise ProtocolError(Text(N_("The master behind {bus} refused the state change of slave {node}: "
                                             "{reason} ({code})"), bus=self.spec, node=node_id,
                                          reason=exc.abort_text, code=f"0x{exc.abort_code:08X}")) from exc
        info = self.slave(node_id)
        if info.al_status is not None and info.al_status & esm.ERROR_FLAG:
            raise ProtocolError(Text(NOT_CHANGED, node=node_id, station=info.station, state=state.label,
                                      reason=info.state_text))
        return info

    def _silence(self) -> Text:
        unreachable = self.gateway.link.unreachable  # an N_() text of the transport
        return Text(N_("{reason} (is the master running with its mailbox gateway on?)"),
                     reason=Text(unreachable or N_("no answer in time")))

    def silence_text(self, station: int, index: int, sub: int) -> Text:
        if self.gateway.link.unreachable:
            return Text(GATEWAY_SILENT, bus=self.spec, reason=self._silence())
        return Text(N_("Slave at station {station} did not answer the mailbox request for {object} within {seconds} "
                        "s: not in Pre-Operational or higher, not on the segment, or slow"),
                     station=station, object=f"0x{index:04X}sub{sub}", seconds=f"{self.sdo_timeout_s:g}")

    @property
    def link_text(self) -> Text | None:
        return Text(GATEWAY_SILENT, bus=self.spec, reason=self._silence()) if self.gateway.link.unreachable else None
