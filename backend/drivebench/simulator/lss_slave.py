"""A simulated device's LSS slave (CiA 305): its 128-bit address, active and pending node ID and bit timing, the
configuration it stored (kept over a power cycle), and its answer to each LSS request.

A device without a node ID (255) is silent except for LSS: the plant gives it no CANopen node until a node ID is
activated (switch state global to waiting after configure node ID), then brings one up with that ID (boot-up). The
plant sends each distinct answer once: identical answers of several devices merge into one frame, as on a CAN bus.
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

from drivebench.device.profiles.profile import Profile
from drivebench.i18n import _
from drivebench.simulator.node import Latency, SimulatedNode
from drivebench.simulator.store import ObjectStore

UNCONFIGURED = 0xFF
ANSWER_COB = 0x7E4
REQUEST_COB = 0x7E5
TIMING_TABLE = {0: 1_000_000, 1: 800_000, 2: 500_000, 3: 250_000, 4: 125_000, 6: 50_000, 7: 20_000, 8: 10_000}
"""CiA 305 bit timing table 0 (index 5 reserved)."""

# command specifiers (CiA 305)
SWITCH_GLOBAL, CONFIGURE_ID, CONFIGURE_TIMING, ACTIVATE_TIMING, STORE = 0x04, 0x11, 0x13, 0x15, 0x17
SELECTIVE = (0x40, 0x41, 0x42, 0x43)
SELECTIVE_ANSWER = 0x44
IDENTIFY = (0x46, 0x47, 0x48, 0x49, 0x4A, 0x4B)
IDENTIFY_NON_CONFIGURED, IDENTIFY_ANSWER, NON_CONFIGURED_ANSWER, FASTSCAN = 0x4C, 0x4F, 0x50, 0x51
INQUIRE = {0x5A: 0, 0x5B: 1, 0x5C: 2, 0x5D: 3}
INQUIRE_ID = 0x5E


class LssState(Enum):
    WAITING = 0
    CONFIGURATION = 1


@dataclass
class StoredSetting:
    """What store configuration kept (the device's non-volatile memory)."""

    node_id: int = UNCONFIGURED
    timing: int | None = None


@dataclass
class LssFaults:
    """Faults of a device's LSS firmware, switched on by a test or a demo (kept over a power cycle)."""

    stays_in_configuration: bool = False
    """It ignores switch state global (waiting): it never leaves configuration state, so a new node ID never
    becomes active."""
    ignores_activate_bit_timing: bool = False
    """It ignores activate bit timing: it stays at its bit rate while the others switch (left behind)."""

    def describe(self) -> list[str]:
        """The active faults in words."""
        words = []
        if self.stays_in_configuration:
            words.append(_("ignores switch state global (waiting): it never leaves LSS configuration state, so a new "
                           "node ID never becomes active"))
        if self.ignores_activate_bit_timing:
            words.append(_("ignores activate bit timing: it stays at its bit rate while the others switch"))
        return words


class LssSlave:
    """``on_node_id(id)`` is called when a node ID becomes active (the plant brings the device up with it)."""

    def __init__(self, address: tuple[int, int, int, int], stored: StoredSetting, bus_timing: int,
                 on_node_id: Callable[[int], None]) -> None:
        self.address = address
        self.stored = stored
        self.bus_timing = bus_timing
        self.on_node_id = on_node_id
        self.faults = LssFaults()
        self.power_on()

    def power_on(self) -> None:
        self.state = LssState.WAITING
        self.active_id = self.pending_id = self.stored.node_id
        self.active_timing = self.pending_timing = (self.stored.timing if self.stored.timing is not None
                                                    else self.bus_timing)
        self._fs_sub = 0
        self._selective = 0
        self._identify: list[int] = []

    @property
    def on_bus(self) -> bool:
        """False while the device runs at a bit rate other than the one the plant's bus was set up with."""
        return self.active_timing == self.bus_timing

    @property
    def bitrate(self) -> int:
        """The bit rate the device runs at now: it hears and sends frames at this rate only."""
        return TIMING_TABLE[self.active_timing]

    @property
    def unconfigured(self) -> bool:
        return self.active_id == UNCONFIGURED

    def on_request(self, data: bytes) -> bytes | None:
        """The answer to one LSS request frame, None for none."""
        data = (data + bytes(8))[:8]
        cs = data[0]
        if cs == SWITCH_GLOBAL:
            self._switch_global(data[1])
        elif cs in SELECTIVE:
            return self._switch_selective(SELECTIVE.index(cs), struct.unpack_from("<I", data, 1)[0])
        elif cs in IDENTIFY:
            return self._identify_remote(IDENTIFY.index(cs), struct.unpack_from("<I", data, 1)[0])
        elif cs == IDENTIFY_NON_CONFIGURED:
            return bytes([NON_CONFIGURED_ANSWER]) + bytes(7) if self._fastscan_candidate() else None
        elif cs == FASTSCAN:
            return self._fastscan(*struct.unpack_from("<IBBB", data, 1))
        elif self.state is LssState.CONFIGURATION:
            return self._configuration(cs, data)
        return None

    def _configuration(self, cs: int, data: bytes) -> bytes | None:
        if cs == CONFIGURE_ID:
            valid = 1 <= data[1] <= 127 or data[1] == UNCONFIGURED
            if valid:
                self.pending_id = data[1]
            return bytes([cs, 0 if valid else 1]) + bytes(6)
        if cs == CONFIGURE_TIMING:
            valid = data[1] == 0 and data[2] in TIMING_TABLE
            if valid:
                self.pending_timing = data[2]
            return bytes([cs, 0 if valid else 1]) + bytes(6)
        if cs == ACTIVATE_TIMING:
            if self.faults.ignores_activate_bit_timing:
                return None
            delay_s = struct.unpack_from("<H", data, 1)[0] / 1000
            threading.Timer(delay_s, self._activate_timing).start()
            return None
        if cs == STORE:
            self.stored = StoredSetting(self.pending_id, self.pending_timing)
            return bytes([cs, 0]) + bytes(6)
        if cs in INQUIRE:
            return bytes([cs]) + struct.pack("<I", self.address[INQUIRE[cs]]) + bytes(3)
        if cs == INQUIRE_ID:
            return bytes([cs, self.active_id]) + bytes(6)
        return None

    def _activate_timing(self) -> None:
        self.active_timing = self.pending_timing

    def _switch_global(self, mode: int) -> None:
        if mode == LssState.CONFIGURATION.value:
            self.state = LssState.CONFIGURATION
            return
        if self.faults.stays_in_configuration and self.state is LssState.CONFIGURATION:
            return
        was = self.state
        self.state = LssState.WAITING
        self._selective = 0
        if was is LssState.CONFIGURATION and self.unconfigured and self.pending_id != UNCONFIGURED:
            self.active_id = self.pending_id  # CiA 305: a device without a node ID starts with the new one
            self.on_node_id(self.active_id)

    def _switch_selective(self, part: int, value: int) -> bytes | None:
        if self.state is not LssState.WAITING:
            return None
        if part != self._selective or value != self.address[part]:
            self._selective = 0
            return None
        self._selective += 1
        if self._selective < 4:
            return None
        self._selective = 0
        self.state = LssState.CONFIGURATION
        return bytes([SELECTIVE_ANSWER]) + bytes(7)

    def _identify_remote(self, step: int, value: int) -> bytes | None:
        if step == 0:
            self._identify = []
        if len(self._identify) != step:
            return None
        self._identify.append(value)
        if step < 5:
            return None
        vendor, product, rev_low, rev_high, serial_low, serial_high = self._identify
        match = (vendor == self.address[0] and product == self.address[1]
                 and rev_low <= self.address[2] <= rev_high and serial_low <= self.address[3] <= serial_high)
        return bytes([IDENTIFY_ANSWER]) + bytes(7) if match else None

    def _fastscan_candidate(self) -> bool:
        return self.unconfigured and self.pending_id == UNCONFIGURED

    def _fastscan(self, value: int, bit_check: int, sub: int, nxt: int) -> bytes | None:
        if self.state is not LssState.WAITING or not self._fastscan_candidate():
            return None
        answer = bytes([IDENTIFY_ANSWER]) + bytes(7)
        if bit_check == 0x80:
            self._fs_sub = 0
            return answer
        if bit_check > 31 or sub != self._fs_sub or sub > 3:
            return None
        mask = (0xFFFFFFFF << bit_check) & 0xFFFFFFFF
        if (value ^ self.address[sub]) & mask:
            return None
        if bit_check == 0:
            if nxt < self._fs_sub:
                self.state = LssState.CONFIGURATION  # all 128 bits matched
                self._fs_sub = 0
            else:
                self._fs_sub = nxt
        return answer


# --- the plant's LSS devices ----------------------------------------------------------------------------------
class DeviceSpec(Protocol):
    """What a plant file says of a device (its node ID may be 255: none yet)."""

    @property
    def node_id(self) -> int: ...
    @property
    def name(self) -> str | None: ...
    @property
    def latency(self) -> str: ...
    @property
    def heartbeat_ms(self) -> int | None: ...
    @property
    def values(self) -> Mapping[str, int | float | str]: ...
    @property
    def serial(self) -> int | None: ...


class LssHost(Protocol):
    """What the LSS devices need of the plant they are on."""

    @property
    def bitrate(self) -> int: ...

    def send_frame(self, cob_id: int, data: bytes, rate: int | None = None) -> None:
        """A device's frame onto the bus at the bit rate it runs at (``None``: the bus's)."""

    def wake(self) -> None: ...

    def attach(self, node: SimulatedNode) -> None:
        """A device's node joins the bus's nodes (as a second device when its node ID is taken)."""

    def detach(self, node: SimulatedNode) -> None:
        """A device's node leaves them (the second device on its node ID, if any, takes its place)."""


@dataclass
class LssDevice:
    spec: DeviceSpec
    profile: Profile
    slave: LssSlave
    latency: str | None
    node: SimulatedNode | None = None


def lss_address(profile: Profile, serial: int | None) -> tuple[int, int, int, int]:
    """The device's identity object 0x1018 sub 1-3 as its object dictionary holds it, and its serial number."""
    store = ObjectStore(profile, 1)
    parts = [int(raw) if store.has(0x1018, sub) and isinstance(raw := store.get(0x1018, sub), int) else 0
             for sub in (1, 2, 3)]
    return parts[0], parts[1], parts[2], serial or 0


class LssDevices:
    """The plant's LSS slaves: each answers every LSS request; the distinct answers go on the bus once each."""

    def __init__(self, plant: LssHost) -> None:
        self._plant = plant
        self.devices: list[LssDevice] = []
        self._lock = threading.Lock()
        bitrate = plant.bitrate
        self.bus_timing = next((index for index, rate in TIMING_TABLE.items() if rate == bitrate), 2)

    def add(self, spec: DeviceSpec, profile: Profile, *, latency: str | None) -> LssDevice:
        stored = StoredSetting(spec.node_id)
        device = LssDevice(spec, profile, LssSlave(lss_address(profile, spec.serial), stored, self.bus_timing,
                                                   lambda node_id: None), latency)
        device.slave.on_node_id = lambda node_id: self._bring_up(device, node_id)
        self.devices.append(device)
        return device

    def by_serial(self, serial: int) -> LssDevice:
        return next(device for device in self.devices if device.slave.address[3] == serial)

    def power_on(self) -> None:
        for device in self.devices:
            device.slave.power_on()
            if not device.slave.unconfigured:
                self._bring_up(device, device.slave.active_id)

    def power_off(self) -> None:
        for device in self.devices:
            self._take_down(device)

    def power_cycle(self) -> None:
        """Every LSS device off and on again: each starts with the configuration it stored."""
        self.power_off()
        self.power_on()

    def rate_of(self, node: SimulatedNode) -> int | None:
        """The bit rate an LSS device's node runs at; None for a node that is no LSS device (the bus's rate)."""
        # asked for every node on every frame (a program download puts 38,000 on the bus): a plain loop, no generator
        for device in self.devices:
            if device.node is node:
                return device.slave.bitrate
        return None

    def on_request(self, data: bytes, rate: int) -> None:
        """An LSS request sent at ``rate``: only the devices at that rate hear it, and answer at it."""
        answers: list[bytes] = []
        with self._lock:
            for device in list(self.devices):
                if device.slave.bitrate != rate:
                    continue
                answer = device.slave.on_request(data)
                if answer is not None and answer not in answers:
                    answers.append(answer)  # identical answers of several devices merge into one frame
        for answer in answers:
            self._plant.send_frame(ANSWER_COB, answer, rate)

    def on_nmt(self, data: bytes, rate: int) -> None:
        """NMT reset communication (or reset node) sent at ``rate``: a device at that rate with a pending node ID
        other than its active one takes it now (CiA 305); a pending 255 leaves it without one (silent except for
        LSS)."""
        if len(data) < 2 or data[0] not in (0x81, 0x82):
            return
        for device in list(self.devices):
            slave = device.slave
            if data[1] not in (0, slave.active_id) or slave.pending_id == slave.active_id or slave.bitrate != rate:
                continue
            slave.active_id = slave.pending_id
            if slave.unconfigured:
                self._take_down(device)
            else:
                self._bring_up(device, slave.active_id)

    def _take_down(self, device: LssDevice) -> None:
        node, device.node = device.node, None
        if node is None:
            return
        self._plant.detach(node)
        node.power_off()

    def _bring_up(self, device: LssDevice, node_id: int) -> None:
        """The device's CANopen node with ``node_id``: it boots (boot-up telegram) and serves SDO, heartbeat ..."""
        self._take_down(device)
        spec, plant = device.spec, self._plant
        slave = device.slave

        def send(cob_id: int, data: bytes) -> None:
            plant.send_frame(cob_id, data, slave.bitrate)

        node = SimulatedNode(device.profile, node_id, send, name=spec.name,
                             latency=Latency.parse(device.latency if device.latency is not None else spec.latency),
                             values=dict(spec.values), heartbeat_ms=spec.heartbeat_ms, bitrate=plant.bitrate)
        if node.store.has(0x1018, 4):
            node.store.set(0x1018, 4, slave.address[3], notify=False)
            node.store.saved[(0x1018, 4)] = slave.address[3]
        node.wake = plant.wake
        device.node = node
        plant.attach(node)
        node.power_on()
