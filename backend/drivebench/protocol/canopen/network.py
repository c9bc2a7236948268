"""Master side of one CAN bus: a canopen Network on an opened bus, with per-node SDO access.

canopen's SDO client blocks and is not thread-safe per node, so every node has one lock per SDO channel, a
:class:`~drivebench.protocol.canopen.sdo_queue.ChannelLock` (``urgent`` transfers, the stop commands, go before waiting
reads); callers in the event loop use the ``a*`` coroutines, which run the blocking call in a worker thread.
All canopen and python-can exceptions are converted here, once, into the protocol error tree.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from typing import TypeVar, cast

import can
import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from drivebench.errors import NodeOffline, ProtocolError, SdoAbortError, TransportError
from drivebench.i18n import N_, Text
from drivebench.protocol.abort_codes import abort_text
from drivebench.protocol.canopen.guarding import NodeGuarding
from drivebench.protocol.canopen.heartbeat import HeartbeatMonitor
from drivebench.protocol.canopen.nmt import NmtCommand, nmt_frame
from drivebench.protocol.canopen.sdo_client import MatchingRemoteNode
from drivebench.protocol.canopen.sdo_domain import download_domain
from drivebench.protocol.canopen.sdo_errors import communication_error, read_segments
from drivebench.protocol.canopen.sdo_queue import ChannelLock
from drivebench.protocol.emcy import EmcyMonitor
from drivebench.protocol.fieldbus import CAN_BUS, NO_FRAMES, EventLoopTransfers, Fieldbus
from drivebench.transport.bus import BusSpec, ObservedBus

T = TypeVar("T")
CANNOT_SEND = N_("Cannot send on {bus}: {reason}")

NOTIFIER_CYCLE_S = 0.1
"""How long the bus reader waits for a frame before it looks whether the session closes (canopen's 1 s made every
close of a quiet bus wait up to a second; a reader waking ten times a second on an idle bus costs nothing measurable).
"""


class SdoChannel:
    """One SDO client (CiA 301 server channel on the device) with its lock."""

    def __init__(self, client: canopen.sdo.SdoClient, number: int) -> None:
        self.client = client
        self.number = number
        self.lock = ChannelLock()


class NodeClient(EventLoopTransfers):
    """SDO access to one node over one or more SDO channels (a device may have more than one)."""

    def __init__(self, network: CanopenNetwork, node_id: int, abort_texts: Mapping[int, str] | None = None) -> None:
        self.network = network
        self.node_id = node_id
        self.abort_texts: dict[int, str] = dict(abort_texts or {})
        """The device manual's abort texts (its profile's ``abort_texts``); updated in place when it changes."""
        self.remote = MatchingRemoteNode(node_id, canopen.ObjectDictionary())  # late answers passed over
        network.canopen.add_node(self.remote)
        self.channels = [SdoChannel(self.remote.sdo, 1)]
        self.configure(network.sdo_timeout_s, network.sdo_retries)

    sdo_information: None = None
    """A CANopen node's object list is its EDS: no SDO information service (CoE's)."""

    @property
    def fast_path(self) -> NodeClient:
        """The client the event loop reads expedited values through (:mod:`drivebench.protocol.canopen.sdo_fast`):
        a CAN node's SDO frames are sent and answered on the loop. A client without one has ``None``."""
        return self

    @property
    def domain_download(self) -> NodeClient:
        """The client that downloads a large domain by block transfer with progress and cancel
        (:meth:`download_domain`: CiA 302-3 program download). A client without one has ``None``."""
        return self

    @property
    def sdo_servers(self) -> NodeClient:
        """The client whose SDO channels can be added (:meth:`add_channel`, the device's additional SDO servers,
        CiA 301 0x1201...). A client with one channel only has ``None``."""
        return self

    def configure(self, timeout_s: float, retries: int) -> None:
        for channel in self.channels:
            channel.client.RESPONSE_TIMEOUT = timeout_s
            channel.client.MAX_RETRIES = retries + 1  # canopen counts attempts, not retries

    def add_channel(self, rx_cobid: int, tx_cobid: int) -> SdoChannel:
        """A second SDO channel (client->server ``rx_cobid``, server->client ``tx_cobid``)."""
        client = self.remote.add_sdo(rx_cobid, tx_cobid)
        client.network = self.remote.network  # canopen 2.4.1 add_sdo subscribes but leaves it unset
        channel = SdoChannel(client, len(self.channels) + 1)
        self.channels.append(channel)
        self.configure(self.channels[0].client.RESPONSE_TIMEOUT, self.channels[0].client.MAX_RETRIES - 1)
        return channel

    def _with_channel(self, index: int, sub: int, work: Callable[[canopen.sdo.SdoClient], T],
                      channel: int | None = None, urgent: bool = False) -> T:
        chosen = self.pick_channel(channel)
        with chosen.lock.held(urgent=urgent):
            try:
                return work(chosen.client)
            except SdoAbortedError as exc:
                raise SdoAbortError(exc.code, abort_text(exc.code, self.abort_texts), node=self.node_id,
                                    index=index, subindex=sub) from exc
            except SdoCommunicationError as exc:
                raise communication_error(exc, node=self.node_id, index=index, subindex=sub) from exc
            except can.CanError as exc:
                raise TransportError(Text(N_("CAN adapter error while talking to node {node}: {reason}"),
                                           node=self.node_id, reason=exc),
                                     hint=N_("Check the adapter connection; the session reconnects when it is back.")
                                     ) from exc

    @contextlib.contextmanager
    def stop_first(self) -> Iterator[None]:
        """Inside, the node's channels serve only urgent transfers: a stop of several transfers (read the control
        word, write it) keeps its place before every waiting read."""
        with contextlib.ExitStack() as stack:
            for channel in self.channels:
                stack.enter_context(channel.lock.reserved())
            yield

    def pick_channel(self, channel: int | None) -> SdoChannel:
        """SDO channel ``channel`` (1 = the default SDO server), or without one the first that is free."""
        if channel is not None:
            if not 1 <= channel <= len(self.channels):
                raise ProtocolError(Text(N_("Node {node} has no SDO channel {channel} configured"),
                                          node=self.node_id, channel=channel))
            return self.channels[channel - 1]
        for candidate in self.channels:
            if not candidate.lock.locked():
                return candidate
        return self.channels[0]

    # --- blocking calls (worker threads) ---------------------------------------------------------------
    def upload(self, index: int, sub: int, *, block: bool = False, channel: int | None = None,
               urgent: bool = False) -> bytes:
        def work(client: canopen.sdo.SdoClient) -> bytes:
            if block:
                with client.open(index, sub, "rb", block_transfer=True) as stream:
                    return bytes(stream.read())
            return read_segments(client, index, sub)

        return self._with_channel(index, sub, work, channel, urgent)

    def download(self, index: int, sub: int, data: bytes, *, block: bool = False,
                 channel: int | None = None, urgent: bool = False) -> None:
        def work(client: canopen.sdo.SdoClient) -> None:
            if block:
                with client.open(index, sub, "wb", size=len(data), block_transfer=True) as stream:
                    stream.write(data)
                return
            client.download(index, sub, data)

        self._with_channel(index, sub, work, channel, urgent)

    def download_domain(self, index: int, sub: int, data: bytes, *, block: bool = True,
                        progress: Callable[[int], None] = lambda _sent: None,
                        cancelled: threading.Event | None = None) -> str:
        """A large DOMAIN (a program image): block transfer, segmented where the device refuses it
        (:func:`~drivebench.protocol.canopen.sdo_domain.download_domain`); ``"block"`` or ``"segmented"``."""
        def work(client: canopen.sdo.SdoClient) -> str:
            return download_domain(client, index, sub, data, block=block, progress=progress, cancelled=cancelled)

        return self._with_channel(index, sub, work, 1)


class CanopenNetwork:
    """canopen Network + heartbeat and EMCY consumers on one opened bus: a
    :class:`~drivebench.protocol.fieldbus.Fieldbus` with frames, NMT, heartbeat and node guarding."""

    capabilities = CAN_BUS

    def __init__(self, bus: ObservedBus, *, sdo_timeout_s: float = 0.5, sdo_retries: int = 1) -> None:
        self.bus = bus
        self.sdo_timeout_s = sdo_timeout_s
        self.sdo_retries = sdo_retries
        self.canopen = canopen.Network(bus)
        self.heartbeat = HeartbeatMonitor()
        self.emcy = EmcyMonitor()
        listeners = cast("list[can.Listener]", self.canopen.listeners)
        self.guarding = NodeGuarding(self.bus.send)
        listeners.extend([self.heartbeat, self.emcy, self.guarding])
        self.canopen.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        self.canopen.connect()
        self.nodes: dict[int, NodeClient] = {}
        self._error: BaseException | None = None
        listeners.append(_ErrorCatcher(self))

    @property
    def spec(self) -> BusSpec:
        return self.bus.spec

    def add_listener(self, listener: can.Listener) -> None:
        """Receive every frame read from the bus (notifier thread)."""
        if self.canopen.notifier is not None:
            self.canopen.notifier.add_listener(listener)

    def remove_listener(self, listener: can.Listener) -> None:
        if self.canopen.notifier is not None:
            self.canopen.notifier.remove_listener(listener)

    def sdo_label(self, node_id: int) -> str:
        """How the node's SDOs travel, for the Parameters tab."""
        return "SDO"

    def node(self, node_id: int, abort_texts: Mapping[int, str] | None = None) -> NodeClient:
        """The node's client; ``abort_texts`` (the profile's, when the caller knows it) replaces the client's."""
        if not 1 <= node_id <= 127:
            raise NodeOffline(Text(N_("Node id {node} is outside 1..127"), node=node_id))
        client = self.nodes.get(node_id)
        if client is None:
            client = self.nodes[node_id] = NodeClient(self, node_id, abort_texts)
        elif abort_texts is not None and abort_texts != client.abort_texts:
            client.abort_texts.clear()
            client.abort_texts.update(abort_texts)
        return client

    def send_nmt(self, command: NmtCommand, node_id: int = 0) -> None:
        self.send(0x000, nmt_frame(command, node_id))

    def send(self, cob_id: int, data: bytes) -> None:
        try:
            self.canopen.send_message(cob_id, data)
        except can.CanError as exc:
            raise TransportError(Text(CANNOT_SEND, bus=self.bus.spec, reason=exc), hint=self.bus.spec.hint()) \
                from exc
        except RuntimeError as exc:  # canopen: "Not connected to CAN bus" once the session has closed
            raise TransportError(Text(CANNOT_SEND, bus=self.bus.spec, reason=Text(
                N_("the session's bus is closed ({reason})"), reason=exc))) from exc

    def scan(self, timeout_s: float = 0.5, node_ids: range = range(1, 128)) -> list[int]:
        """Ask every node id for 0x1000 (SDO) and collect who answers or sends heartbeats (blocking).

        An id whose default SDO identifiers a known node's additional SDO channel uses is not asked: the device
        behind that channel would answer for it (an SDO2 of node 5 on 0x645/0x5C5 is node 69's SDO1), and the scan
        would list a node that is not there."""
        found: set[int] = set()
        borrowed = {channel.client.rx_cobid for client in self.nodes.values() for channel in client.channels[1:]}
        asked = [node_id for node_id in node_ids if 0x600 + node_id not in borrowed]

        def on_frame(can_id: int, data: bytearray, timestamp: float) -> None:
            found.add(can_id - 0x580)

        locks = [ch.lock for client in self.nodes.values() for ch in client.channels]
        for lock in locks:  # no scan request may land in the middle of a transfer
            lock.acquire()
        for node_id in asked:
            self.canopen.subscribe(0x580 + node_id, on_frame)
        try:
            for node_id in asked:
                self.send(0x600 + node_id, bytes([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]))
            time.sleep(timeout_s)
        finally:
            for node_id in asked:
                self.canopen.unsubscribe(0x580 + node_id, on_frame)
            for lock in locks:
                lock.release()
        now = time.time()
        for status in self.heartbeat.all():
            if status.age_s(now) is not None and (status.age_s(now) or 0) < max(timeout_s * 4, 2.0):
                found.add(status.node_id)
        return sorted(n for n in found if 1 <= n <= 127)

    @property
    def bus_state(self) -> str:
        try:
            return self.bus.state.name.lower()
        except (NotImplementedError, AttributeError):
            return "active"

    def close(self) -> None:
        self.guarding.close()
        try:
            self.canopen.disconnect()
        finally:
            self.bus.shutdown()


def frames_of(network: Fieldbus[object]) -> CanopenNetwork:
    """The CAN network behind a session's fieldbus, for what needs frames by identifier (NMT, PDOs, SYNC, frame
    listeners, the adapter); a bus without frames refuses in words."""
    if not network.capabilities.frames:
        raise ProtocolError(Text(NO_FRAMES, bus=network.spec))
    return cast(CanopenNetwork, network)


class _ErrorCatcher(can.Listener):
    """Keeps the notifier's last reader error (e.g. the adapter was unplugged) instead of losing it."""

    def __init__(self, network: CanopenNetwork) -> None:
        self.network = network

    def on_message_received(self, msg: can.Message) -> None:
        pass

    def on_error(self, exc: Exception) -> None:
        self.network._error = exc
