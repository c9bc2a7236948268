"""Sessions: one per bus, each with its own network (a canopen network on a CAN bus, or an EtherCAT segment behind
a mailbox gateway: :mod:`drivebench.services.bus.fieldbus`), nodes and their profiles.

Everything that touches the bus runs in worker threads (``asyncio.to_thread``); the event loop only awaits.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can

from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.profile import Profile
from drivebench.errors import DriveBenchError, NotFound, SdoAbortError, SdoOutOfStepError, SdoTimeoutError
from drivebench.i18n import _
from drivebench.protocol.canopen.guarding import NodeGuarding
from drivebench.protocol.canopen.heartbeat import HeartbeatMonitor, HeartbeatStatus
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.canopen.nmt import STATE_AFTER, NmtCommand, NmtState
from drivebench.protocol.emcy import EmcyEvent
from drivebench.protocol.ethercat.esm import EsmState
from drivebench.protocol.ethercat.network import EthercatNetwork, SlaveInfo, master_of
from drivebench.services.bus.bus_state import ADAPTER_LOST, BusHealth, GatewayHealth
from drivebench.services.bus.duplicates import DuplicateWatch
from drivebench.services.bus.fieldbus import Network, SdoClient, SessionSpec


class SessionServicesBase(Protocol):
    """What the session knows of its services' container (``session_manager.SessionServices``): the services sit
    above the bus in the layers, so the session names none of them."""

    def close(self, session: Session) -> None: ...


class ProfileSource(Protocol):
    def get(self, profile_id: str) -> Profile: ...

    def find_by_identity(self, vendor_id: int | None, product_code: int | None) -> Profile | None: ...

    def all(self) -> list[Profile]: ...


@dataclass
class SessionNode:
    """A node the session knows: its id, the profile it is handled with, and what the tool last commanded."""

    node_id: int
    profile: Profile | None
    name: str | None = None
    commanded_state: NmtState | None = None
    identity: dict[str, int] = field(default_factory=dict)
    pending_reset: set[str] = field(default_factory=set)
    """Refs written since the last reset node that take effect only after one (C00350, C00351 ...)."""

    @property
    def catalog(self) -> Catalog | None:
        return None if self.profile is None else catalog_for(self.profile)

    @property
    def device_name(self) -> str:
        if self.name:
            return self.name
        if self.profile:
            return self.profile.identity.product_name
        if "vendor_id" in self.identity:  # scanned, but no profile matches its 0x1018 identity
            return _("Unknown device (vendor {vendor}, product {product})").format(
                vendor=f"0x{self.identity['vendor_id']:08X}", product=f"0x{self.identity.get('product_code', 0):08X}")
        return _("Unknown device")


ESM_FOR_NMT = {
    NmtCommand.START: [EsmState.OPERATIONAL],
    NmtCommand.ENTER_PRE_OPERATIONAL: [EsmState.PRE_OPERATIONAL],
    NmtCommand.STOP: [EsmState.SAFE_OPERATIONAL],
    NmtCommand.RESET_COMMUNICATION: [EsmState.INIT, EsmState.PRE_OPERATIONAL],
    NmtCommand.RESET_NODE: [EsmState.INIT, EsmState.PRE_OPERATIONAL],
}
"""On EtherCAT, the state an NMT command's job asks for: start -> Operational (the drive acts on process data),
stop -> Safe-Operational (outputs in their safe state; SDO still works, unlike NMT Stopped), reset -> through Init
back to Pre-Operational (the master re-initialises the slave)."""


class Session:
    def __init__(self, session_id: str, name: str, spec: SessionSpec, network: Network,
                 profiles: ProfileSource, *, simulated: bool = False) -> None:
        self.id = session_id
        self.name = name
        self.spec = spec
        self.network = network
        self.profiles = profiles
        self.simulated = simulated
        self.opened_at = time.time()
        self.nodes: dict[int, SessionNode] = {}
        self.services: SessionServicesBase | None = None
        """What the services keep for this session (its monitor, leases, guard, recordings ...) as typed attributes:
        made by :class:`~drivebench.services.session_manager.SessionManager` when the session opens, closed with it.
        A service reaches its part with :meth:`opened_services`."""
        self._lock = threading.Lock()
        self._listeners: list[Callable[[str, dict[str, object]], None]] = []
        self.duplicates = DuplicateWatch()
        self.slaves: dict[int, SlaveInfo] = {}
        self._states_read = 0.0
        """EtherCAT only: what the master last said about each slave (station address, AL status)."""
        self.health: BusHealth | GatewayHealth
        master = master_of(network)
        if master is not None:
            self.health = GatewayHealth(master)
            return
        frames = frames_of(network)
        self.health = BusHealth(frames.bus, self.emit)
        frames.add_listener(self.health)
        frames.bus.send_guard = self.health.refusal
        frames.add_listener(self.duplicates)
        self.health.notes.append(self.duplicates.text)

    def opened_services(self) -> Any:
        """The services' container, to be seen through a Protocol in the service's own module that names the typed
        attribute it uses (``services: MonitorPart = session.opened_services()``); the container is checked
        against every such view where it is built (``session_manager.views``)."""
        if self.services is None:
            raise RuntimeError(f"session '{self.id}' has no services: it was not opened by a SessionManager")
        return self.services

    @property
    def parts(self) -> dict[type, object]:
        """The container's parts by class, read from its attributes (for a look at them; services use
        :meth:`opened_services`)."""
        return {type(part): part for part in vars(self.services).values()} if self.services is not None else {}

    @property
    def ethercat(self) -> EthercatNetwork | None:
        """The master of the session's EtherCAT segment (slave list, AL states, mailbox counters), or None on a bus
        without one (CAN)."""
        return master_of(self.network)

    # --- nodes ------------------------------------------------------------------------------------------
    def add_node(self, node_id: int, profile_id: str | None, name: str | None = None) -> SessionNode:
        profile = self.profiles.get(profile_id) if profile_id else None
        with self._lock:
            node = SessionNode(node_id, profile, name)
            self.nodes[node_id] = node
        self.client(node_id)
        return node

    def node(self, node_id: int) -> SessionNode:
        node = self.nodes.get(node_id)
        if node is None:
            raise NotFound(_("Node {node} is not part of session '{session}'. Scan the bus or add it.").format(
                node=node_id, session=self.name))
        return node

    def client(self, node_id: int) -> SdoClient:
        node = self.nodes.get(node_id)
        if node is None:
            return self.network.node(node_id)
        texts = node.profile.abort_texts if node.profile else None
        return self.network.node(node_id, texts.texts if texts else {})

    def remove_node(self, node_id: int) -> None:
        with self._lock:
            self.nodes.pop(node_id, None)

    # --- NMT --------------------------------------------------------------------------------------------
    async def nmt(self, command: NmtCommand, node_id: int = 0) -> None:
        """NMT on CAN; on EtherCAT the state change that does the same job (:data:`ESM_FOR_NMT`), so the safety
        guard's confirmation and keep-alive hold there too."""
        if node_id and node_id not in self.nodes:
            self.node(node_id)
        master = self.ethercat
        if master is not None:
            await self._change_states(master, command, node_id)
            return
        await asyncio.to_thread(frames_of(self.network).send_nmt, command, node_id)
        targets = list(self.nodes.values()) if node_id == 0 else [self.nodes[node_id]]
        for node in targets:
            node.commanded_state = STATE_AFTER[command]
            if command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
                node.pending_reset.clear()
        self.emit("nmt", {"command": command.label, "node": node_id})

    async def _change_states(self, segment: EthercatNetwork, command: NmtCommand, node_id: int) -> None:
        targets = [node_id] if node_id else sorted(self.nodes)
        for target in targets:
            try:
                for state in ESM_FOR_NMT[command]:
                    self.slaves[target] = await asyncio.to_thread(segment.request_state, target, state)
            finally:
                with contextlib.suppress(DriveBenchError):
                    self.slaves[target] = await asyncio.to_thread(segment.slave, target)
        self.emit("nmt", {"command": ESM_FOR_NMT[command][-1].label, "node": node_id})

    async def refresh_states(self, max_age_s: float = 2.0) -> None:
        """EtherCAT: the slaves' AL status read from the master again, at most every ``max_age_s`` however many
        pages ask (on CAN the heartbeats keep the states live; nothing to do)."""
        master = self.ethercat
        if master is None or time.monotonic() - self._states_read < max_age_s:
            return
        self._states_read = time.monotonic()
        for node_id, info in list(self.slaves.items()):
            try:
                info.al_status, info.al_status_code = await asyncio.to_thread(master.al_state, node_id)
            except DriveBenchError:
                info.al_status, info.al_status_code = None, 0  # shown as Unknown: the master did not say

    # --- scan -------------------------------------------------------------------------------------------
    async def scan(self, timeout_s: float = 0.5) -> list[SessionNode]:
        """Find nodes (SDO 0x1000 to every id + heartbeats), read their identity, pick a profile."""
        master = self.ethercat
        if master is not None:
            return await self._scan_segment(master)
        found = await asyncio.to_thread(self.network.scan, timeout_s)
        results = await asyncio.gather(*(self._identify(node_id) for node_id in found))
        if found:  # two devices on one id both answer: one more request each tells (Plant page, state_text)
            await asyncio.to_thread(self.duplicates.probe, frames_of(self.network), found)
        return list(results)

    async def _scan_segment(self, segment: EthercatNetwork) -> list[SessionNode]:
        """The slaves the master has configured, with their identity from its configuration objects."""
        found = await asyncio.to_thread(segment.scan)
        nodes = []
        for node_id in found:
            info = await asyncio.to_thread(segment.slave, node_id)
            self.slaves[node_id] = info
            existing = self.nodes.get(node_id)
            profile = existing.profile if existing else None
            if profile is None:
                profile = self.profiles.find_by_identity(info.vendor_id, info.product_code)
            node = existing or SessionNode(node_id, profile, info.name or None)
            node.profile = profile
            node.identity = {key: value for key, value in (("vendor_id", info.vendor_id),
                                                           ("product_code", info.product_code),
                                                           ("revision", info.revision),
                                                           ("station", info.station)) if value is not None}
            with self._lock:
                self.nodes[node_id] = node
            nodes.append(node)
        return nodes

    async def identify(self, node_id: int) -> SessionNode:
        """One node joins the session: its identity read, its profile picked (a node just addressed by LSS)."""
        return await self._identify(node_id)

    async def _identify(self, node_id: int) -> SessionNode:
        client = self.network.node(node_id)
        identity: dict[str, int] = {}
        for key, (index, sub) in {"device_type": (0x1000, 0), "vendor_id": (0x1018, 1),
                                   "product_code": (0x1018, 2), "revision": (0x1018, 3),
                                   "serial": (0x1018, 4)}.items():
            try:
                data = await client.aupload(index, sub)
                identity[key] = int.from_bytes(data[:4], "little")
            except (SdoAbortError, SdoTimeoutError, SdoOutOfStepError):
                # out of step: a late second answer to the read before (two devices on this id; the duplicate
                # probe after the scan says so in words). One node's unreliable answers must not fail the scan.
                continue
        try:  # the producer period lets heartbeat loss be judged before two telegrams were measured
            period = await client.aupload(0x1017, 0)
            period_ms = int.from_bytes(period[:2], "little")
            frames_of(self.network).heartbeat.set_configured_period(node_id, period_ms)
            if period_ms:
                self.duplicates.producer_period_s[node_id] = period_ms / 1000
        except (SdoAbortError, SdoTimeoutError, SdoOutOfStepError):
            pass
        existing = self.nodes.get(node_id)
        profile = existing.profile if existing else None
        if profile is None:
            profile = self.profiles.find_by_identity(identity.get("vendor_id"), identity.get("product_code"))
        node = existing or SessionNode(node_id, profile)
        node.profile = profile
        node.identity = identity
        with self._lock:
            self.nodes[node_id] = node
        return node

    # --- state ------------------------------------------------------------------------------------------
    @property
    def heartbeats(self) -> HeartbeatMonitor | None:
        """The heartbeat consumer, or None on a bus without heartbeats (EtherCAT: the master watches its slaves)."""
        return frames_of(self.network).heartbeat if self.network.capabilities.heartbeat else None

    @property
    def guarding(self) -> NodeGuarding | None:
        """Node guarding, or None on a bus without it."""
        return frames_of(self.network).guarding if self.network.capabilities.guarding else None

    def heartbeat(self, node_id: int) -> HeartbeatStatus:
        """What the node's heartbeats said (nothing heard on a bus without heartbeats)."""
        heartbeats = self.heartbeats
        return heartbeats.status(node_id) if heartbeats is not None else HeartbeatStatus(node_id)

    @property
    def bus_state(self) -> str:
        """``active``, ``warning``, ``passive``, ``bus-off`` or ``adapter lost``."""
        return self.health.state()

    @property
    def bus_text(self) -> str | None:
        """The bus state in a sentence when it is not plainly fine (adapter lost, bus-off, back again ...)."""
        return self.health.text()

    def reconnect(self) -> None:
        """Try to reopen a lost adapter now (it is retried with back-off anyway)."""
        if self.network.capabilities.frames:
            frames_of(self.network).bus.reconnect_now()

    def nmt_state(self, node_id: int) -> tuple[str, bool]:
        """The node's NMT state in words, and whether it comes from a live heartbeat (on EtherCAT: its AL status
        as the master last reported it)."""
        slave = self.slaves.get(node_id)
        if self.network.capabilities.esm:
            return (slave.state_text, slave.al_status is not None) if slave is not None else ("Unknown", False)
        bus_state = self.health.state()
        if bus_state == ADAPTER_LOST:
            return "Adapter lost", False
        if bus_state == "bus-off":
            return "Bus-off", False
        guard = frames_of(self.network).guarding.status(node_id)
        if guard is not None:
            if guard.is_lost():
                return "Node guarding lost", True
            if guard.state is not None:
                return guard.state.label, True
        status = self.heartbeat(node_id)
        if status.state is not None and not status.is_lost():
            return status.state.label, True
        if status.state is not None and status.is_lost():
            return "Heartbeat lost", True
        node = self.nodes.get(node_id)
        if node and node.commanded_state is not None:
            return f"{node.commanded_state.label} (commanded)", False
        return "Unknown", False

    def last_emcy(self, node_id: int) -> EmcyEvent | None:
        return self.network.emcy.last(node_id)

    def add_frame_listener(self, listener: can.Listener) -> None:
        """Frames read from the bus and frames the tool sends (e.g. the monitor); EtherCAT has none."""
        if not self.network.capabilities.frames:
            return
        frames = frames_of(self.network)
        frames.add_listener(listener)
        frames.bus.add_observer(listener.on_message_received)

    def remove_frame_listener(self, listener: can.Listener) -> None:
        if not self.network.capabilities.frames:
            return
        frames = frames_of(self.network)
        frames.remove_listener(listener)
        frames.bus.remove_observer(listener.on_message_received)

    def on_event(self, callback: Callable[[str, dict[str, object]], None]) -> None:
        self._listeners.append(callback)

    def emit(self, kind: str, data: dict[str, object]) -> None:
        for callback in self._listeners:
            callback(kind, data)

    def close(self) -> None:
        self.network.close()
