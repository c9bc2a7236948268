"""A simulated plant: simulated drives on one CAN bus, described by a small JSON file.

Example (``plants/demo.json`` is the one ``make run`` starts)::

    {"name": "Demo plant", "bus": "virtual:drivebench-demo@500000",
     "nodes": [{"node_id": 5, "profile": "lenze-8400-motec-canopen", "latency": "30ms±20ms",
                "heartbeat_ms": 500, "values": {"C00061": 43}}]}

The plant's CAN nodes speak only CAN: it opens its own python-can bus (``virtual`` in-process, or ``socketcand`` to a
hub or gateway), so the tool's protocol layer cannot tell it from real drives. Its ``ethercat`` section puts EtherCAT
slaves behind a simulated master's mailbox gateway on UDP (:mod:`drivebench.simulator.ethercat`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import can
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from drivebench.device.profiles.profile import Profile
from drivebench.errors import DriveBenchError, ProfileError, TransportError
from drivebench.i18n import _
from drivebench.simulator.babbler import DEFAULT_COB_ID, Babbler
from drivebench.simulator.ethercat import EthercatLine
from drivebench.simulator.lss_slave import REQUEST_COB as LSS_REQUEST
from drivebench.simulator.lss_slave import UNCONFIGURED, LssDevices, LssFaults
from drivebench.simulator.node import Latency, LatencyText, SimulatedNode
from drivebench.simulator.servo402 import Servo402
from drivebench.simulator.ticker import DeadlineTicker
from drivebench.transport.bus import BusSpec, RatedFrame, open_bus, rate_of

NOTIFIER_CYCLE_S = 0.05
"""How long the plant's bus reader waits for a frame before it looks whether it should stop: stopping a plant waits
for it (0.5 s cost every test app with the demo plant half a second at its end; an idle reader waking 20 times a
second costs nothing measurable, benchmarks/idle_cpu.py)."""


class PlantLssFaults(BaseModel):
    """``"lss_faults": {"ignores_activate_bit_timing": true}`` in a plant file (:class:`LssFaults`)."""

    model_config = ConfigDict(extra="forbid")

    stays_in_configuration: bool = False
    """It ignores switch state global (waiting): its new node ID never becomes active."""
    ignores_activate_bit_timing: bool = False
    """It stays at its bit rate when the others switch (left behind)."""


class PlantNode(BaseModel):
    model_config = ConfigDict(extra="forbid")

    node_id: int = Field(ge=1, le=255)
    """1-127; 255: the device arrives without a node ID (an LSS slave, silent except for LSS until addressed)."""
    profile: str
    name: str | None = None
    latency: LatencyText = "0ms"
    heartbeat_ms: int | None = Field(None, ge=0, le=65535)
    values: dict[str, int | float | str] = Field(default_factory=dict)
    """Initial values by parameter reference (``C00061``, ``0x1017``), in engineering units."""
    trip_current_permille: int | None = Field(None, ge=1)
    """A CiA 402 servo trips on overcurrent (0x2310) above this current (per mille of rated; an acceleration's
    current spike can reach it); None: it never does."""
    lss: bool = False
    """The device is an LSS slave (CiA 305); always so with node_id 255."""
    serial: int | None = Field(None, ge=0, le=0xFFFFFFFF)
    """Its serial number (0x1018 sub 4, part of its LSS address)."""
    lss_faults: PlantLssFaults | None = None
    """Faults of its LSS firmware (an LSS device only), for demos and tests of what goes wrong on a new line."""

    @field_validator("node_id")
    @classmethod
    def _node_id(cls, node_id: int) -> int:
        if 127 < node_id < 255:
            raise ValueError(_("node id {node} is out of range: 1-127, or 255 for a device without one").format(
                node=node_id))
        return node_id

    @model_validator(mode="after")
    def _faults_of_an_lss_device(self) -> PlantNode:
        if self.lss_faults is not None and not (self.lss or self.node_id == UNCONFIGURED):
            raise ValueError(_("node {node}: lss_faults need an LSS device (\"lss\": true, or node_id 255)").format(
                node=self.node_id))
        return self


class PlantFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str
    bus: str = "virtual:drivebench-plant@500000"
    nodes: list[PlantNode] = Field(default_factory=list)
    ethercat: EthercatLine | None = None
    """Slaves behind a simulated EtherCAT master's mailbox gateway (a second session next to the CAN bus)."""

    @field_validator("nodes")
    @classmethod
    def _unique_ids(cls, nodes: list[PlantNode]) -> list[PlantNode]:
        seen: set[int] = set()
        for node in nodes:
            if node.node_id == UNCONFIGURED:
                continue
            if node.node_id in seen:
                raise ValueError(_("node id {node} appears twice").format(node=node.node_id))
            seen.add(node.node_id)
        return nodes

    @classmethod
    def load(cls, path: Path) -> PlantFile:
        try:
            return cls.model_validate_json(path.read_text(encoding="utf-8"))
        except (OSError, ValidationError, ValueError) as exc:
            raise ProfileError(_("invalid plant file: {reason}").format(reason=exc), source=path.name) from exc


ProfileLookup = Callable[[str], Profile]


class Plant:
    """Runs the simulated nodes of a plant file on a bus until :meth:`stop`."""

    def __init__(self, plant: PlantFile, profiles: ProfileLookup, *, bus: str | None = None,
                 latency: str | None = None) -> None:
        self.plant = plant
        self.spec = BusSpec.parse(bus or plant.bus)
        self.nodes: dict[int, SimulatedNode] = {}
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._ticker = DeadlineTicker(self._everyone, "sim-plant-ticker")
        self._send_lock = threading.Lock()
        self.babbler: Babbler | None = None
        self.duplicates: list[SimulatedNode] = []
        """Second devices set to a node id that is already taken (a commissioning mistake, switched at run time)."""
        self.lss = LssDevices(self)
        """The devices that are LSS slaves (CiA 305): those of the plant file with ``lss`` or node_id 255."""
        for spec in plant.nodes:
            profile = profiles(spec.profile)
            if spec.lss or spec.node_id == UNCONFIGURED:
                device = self.lss.add(spec, profile, latency=latency)
                if spec.lss_faults is not None:
                    device.slave.faults = LssFaults(**spec.lss_faults.model_dump())
                continue
            self.nodes[spec.node_id] = node = SimulatedNode(
                profile, spec.node_id, self._send, name=spec.name,
                latency=Latency.parse(latency if latency is not None else spec.latency),
                values=spec.values, heartbeat_ms=spec.heartbeat_ms, bitrate=self.spec.bitrate)
            node.wake = self.wake
            if spec.trip_current_permille is not None and isinstance(node.drive, Servo402):
                node.drive.trip_current = float(spec.trip_current_permille)

    def start(self) -> Plant:
        self._bus = open_bus(self.spec)
        if self._bus.adapter is not None:  # a virtual bus: each device hears and sends at the rate it runs at
            self._bus.adapter.every_rate = True
        self._notifier = can.Notifier(self._bus, [self._on_message], timeout=NOTIFIER_CYCLE_S)
        for node in self.nodes.values():
            node.power_on()
        self.lss.power_on()
        self._ticker.start()
        return self

    def stop(self) -> None:
        self.stop_babbler()
        self._ticker.stop()
        for node in self._everyone():
            node.power_off()
        self.lss.power_off()
        if self._notifier is not None:
            self._notifier.stop()
        if self._bus is not None:
            self._bus.shutdown()

    def add_node(self, profile: Profile, node_id: int, *, duplicate: bool = False,
                 **kwargs: object) -> SimulatedNode:
        """A node powered on now; ``duplicate`` puts a second device on an id that is taken (both answer)."""
        if node_id in self.nodes and not duplicate:
            raise DriveBenchError(_("Node id {node} is already on the simulated bus").format(node=node_id))
        kwargs.setdefault("bitrate", self.spec.bitrate)
        node = SimulatedNode(profile, node_id, self._send, **kwargs)  # type: ignore[arg-type]
        node.wake = self.wake
        self.attach(node)
        if self._bus is not None:
            node.power_on()
        return node

    @property
    def bitrate(self) -> int:
        return self.spec.bitrate

    def attach(self, node: SimulatedNode) -> None:
        """``node`` joins the bus's nodes (as a second device when its node id is taken)."""
        if node.node_id in self.nodes:
            self.duplicates = [*self.duplicates, node]
        else:
            self.nodes[node.node_id] = node

    def detach(self, node: SimulatedNode) -> None:
        """``node`` leaves them; a second device on its node id takes its place."""
        if self.nodes.get(node.node_id) is node:
            del self.nodes[node.node_id]
            spare = next((other for other in self.duplicates if other.node_id == node.node_id), None)
            if spare is not None:
                self.duplicates = [other for other in self.duplicates if other is not spare]
                self.nodes[node.node_id] = spare
        else:
            self.duplicates = [other for other in self.duplicates if other is not node]

    def remove_duplicates(self, node_id: int) -> None:
        """Take the second devices on ``node_id`` off the bus again."""
        gone = [node for node in self.duplicates if node.node_id == node_id]
        self.duplicates = [node for node in self.duplicates if node.node_id != node_id]
        for node in gone:
            node.power_off()

    def _everyone(self) -> list[SimulatedNode]:
        return [*self.nodes.values(), *self.duplicates]

    # --- a babbling node (switchable at run time) ------------------------------------------------------------
    def start_babbler(self, cob_id: int = DEFAULT_COB_ID, *, load_percent: float = 100.0) -> Babbler:
        """A node that floods the bus with ``cob_id``; at 100 % the plant's nodes with higher COB-IDs lose every
        arbitration, as on a real bus, so their answers and heartbeats stop until :meth:`stop_babbler`."""
        self.stop_babbler()
        self.babbler = Babbler(self.spec, cob_id, load_percent=load_percent).start()
        return self.babbler

    def stop_babbler(self) -> None:
        babbler, self.babbler = self.babbler, None
        if babbler is not None:
            babbler.stop()

    def send_frame(self, cob_id: int, data: bytes, rate: int | None = None) -> None:
        """A frame from a device of the plant onto the bus at the rate it runs at (``None``: the bus's); its other
        devices at that rate hear it."""
        self._send(cob_id, data, rate)

    def _send(self, cob_id: int, data: bytes, rate: int | None = None) -> None:
        babbler = self.babbler
        if babbler is not None and babbler.starves(cob_id):
            return  # never wins arbitration against the babbler: the frame does not get on the bus
        rate = rate or self.spec.bitrate
        msg = RatedFrame.at(rate, arbitration_id=cob_id, data=data, is_extended_id=False)
        with self._send_lock:
            if self._bus is None:
                return
            try:
                self._bus.send(msg)
            except TransportError:  # the plant's own link is down (hub gone): the frame is lost, as on a wire
                return
        # Nodes on a real bus hear each other; a python-can bus does not echo its own frames.
        self._dispatch(cob_id, data, time.time(), rate, skip_sender=True)

    def _on_message(self, msg: can.Message) -> None:
        if msg.is_extended_id or msg.is_error_frame:
            return
        rate = rate_of(msg) or self.spec.bitrate  # a frame of unknown rate was sent at the bus's
        if msg.arbitration_id == LSS_REQUEST and not msg.is_remote_frame:
            self.lss.on_request(bytes(msg.data), rate)
            return
        if msg.is_remote_frame:
            for node in self._everyone():
                if (self.lss.rate_of(node) or self.spec.bitrate) == rate:
                    node.on_remote_request(msg.arbitration_id)
            return
        self._dispatch(msg.arbitration_id, bytes(msg.data), msg.timestamp, rate, skip_sender=False)
        if msg.arbitration_id == 0:
            self.lss.on_nmt(bytes(msg.data), rate)

    def _dispatch(self, cob_id: int, data: bytes, timestamp: float, rate: int, *, skip_sender: bool) -> None:
        """Every node at ``rate`` hears the frame (one at another bit rate hears nothing)."""
        bus_rate = self.spec.bitrate
        for node in self._everyone():
            if skip_sender and cob_id & 0x7F == node.node_id:
                continue
            if (self.lss.rate_of(node) or bus_rate) != rate:
                continue
            node.on_frame(cob_id, data, timestamp)

    def wake(self) -> None:
        """Something changed (any thread): the nodes are ticked now rather than at the next deadline."""
        self._ticker.wake()
