"""A simulated drive: a real CANopen slave on the bus, built from a device profile.

It answers SDO on its SDO channels (the protocol's SdoServer over this node's ObjectStore), follows NMT
(reset node / reset communication reload values, send boot-up and return to pre-operational), produces
heartbeats per 0x1017, sends EMCY telegrams, and transmits/receives PDOs per its mapping (see ``pdo.py``).
Frames reach it from the plant's dispatcher; it sends through the plant's ``send``.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import random
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Annotated

from pydantic import AfterValidator

from drivebench.device.profiles.profile import Profile
from drivebench.errors import UnknownParameter
from drivebench.protocol.canopen.nmt import NmtCommand, NmtState
from drivebench.protocol.canopen.sdo_server import SdoAbort as Abort
from drivebench.protocol.canopen.sdo_server import SdoServer
from drivebench.simulator.drive402 import Drive402
from drivebench.simulator.faults import FaultState
from drivebench.simulator.lenze_control import WordControl
from drivebench.simulator.pdo import PdoEngine
from drivebench.simulator.program_store import ProgramStore
from drivebench.simulator.servo402 import Servo402
from drivebench.simulator.store import ObjectStore, RawValue
from drivebench.simulator.telegram_counters import DeviceTelegramCounters

log = logging.getLogger(__name__)
Send = Callable[[int, bytes], None]

UNTIMED_DRIVE_TICK_S = 0.002
"""How often a drive model without ``next_tick()`` (its own deadline, None at rest) is cycled."""
SDO_IDLE_S = 3.0
"""A transfer the client leaves idle this long is dropped (the client vanished). Not 1 s: a client held up that long
between two sub-blocks of a program download (a loaded host) had its transfer dropped and the rest of its frames
read as new requests."""
SAVE_SIGNATURE = int.from_bytes(b"save", "little")
LOAD_SIGNATURE = int.from_bytes(b"load", "little")
DEVICE_COMMAND_SAVE, DEVICE_COMMAND_RESET_NODE = 11, 26
"""Subcodes of a device-command code (8400 motec CANopen manual: C00002/11 save all parameter sets, C00002/26 CAN
reset node); the code is the one the profile's save command writes."""


@dataclass(frozen=True)
class Latency:
    """SDO processing time: ``mean_s`` ± ``jitter_s`` (uniform)."""

    mean_s: float = 0.0
    jitter_s: float = 0.0

    @classmethod
    def parse(cls, text: str | float | None) -> Latency:
        """``"30ms±20ms"``, ``"30ms+-20ms"``, ``"0.03"``, ``30`` (ms) or None."""
        if text is None or text == "":
            return cls()
        if isinstance(text, (int, float)):
            return cls(float(text) / 1000)
        cleaned = text.replace(" ", "").replace("+-", "±").lower()
        mean, _, jitter = cleaned.partition("±")
        return cls(_seconds(mean), _seconds(jitter) if jitter else 0.0)

    def sample(self) -> float:
        if self.jitter_s:
            return max(0.0, self.mean_s + random.uniform(-self.jitter_s, self.jitter_s))
        return self.mean_s

    def __str__(self) -> str:
        if not self.mean_s and not self.jitter_s:
            return "0 ms"
        jitter = f" ± {self.jitter_s * 1000:g} ms" if self.jitter_s else ""
        return f"{self.mean_s * 1000:g} ms{jitter}"


def _checked_latency(text: str) -> str:
    Latency.parse(text)
    return text


LatencyText = Annotated[str, AfterValidator(_checked_latency)]
"""A plant file's latency field (``"30ms±20ms"``), checked when the file is read."""


def _device_control(node: SimulatedNode) -> Drive402 | WordControl | Servo402 | None:
    """The drive model the profile's control section names (``simulation``); a profile without one whose objects
    have 0x6040/0x6041 is a generic CiA 402 servo."""
    control = node.profile.control
    if control is not None:
        model = control.simulation
    else:
        model = "cia402_servo" if node.store.has(0x6040, 0) and node.store.has(0x6041, 0) else None
    if model == "cia402_vf_inverter":
        return Drive402(node)
    if model == "cia402_servo":
        return Servo402(node)
    words = WordControl.words_for(node, model)
    return WordControl(node, words) if words is not None else None


def _device_command_code(profile: Profile, store: ObjectStore) -> tuple[int, int] | None:
    """(index, value) of the device-command code the profile's save command writes at its save subcode
    (``C00002/11`` := 1 -> (0x5FFD, 1)); None where the device saves otherwise (CiA 301 0x1010)."""
    save = profile.commands.save if profile.commands is not None else None
    if save is None or not isinstance(save.value, int):
        return None
    try:
        item = store.catalog.resolve(save.ref)
    except UnknownParameter:
        return None
    return (item.index, save.raw) if item.subindex == DEVICE_COMMAND_SAVE else None


def _seconds(text: str) -> float:
    if text.endswith("ms"):
        return float(text[:-2]) / 1000
    if text.endswith("us") or text.endswith("µs"):
        return float(text[:-2]) / 1e6
    if text.endswith("s"):
        return float(text[:-1])
    return float(text) / 1000  # a bare number is milliseconds


def _no_wake() -> None:
    """A node outside a plant is ticked by whoever drives it."""


class SimulatedNode:
    def __init__(self, profile: Profile, node_id: int, send: Send, *, name: str | None = None,
                 latency: Latency | None = None, values: Mapping[str, object] | None = None,
                 heartbeat_ms: int | None = None, bitrate: int | None = None) -> None:
        self.profile = profile
        self.node_id = node_id
        self.name = name or profile.identity.product_name
        self.latency = latency or Latency()
        self._send = send
        # a device on this bus was configured for its node id and bit rate: its setting parameters say so
        configured = (profile.switches.configured_values(node_id, bitrate)
                      if profile.switches is not None and bitrate is not None else {})
        self.store = ObjectStore(profile, node_id, {**configured, **(values or {})})
        self._device_command_code = _device_command_code(profile, self.store)
        self.telegram_counters = DeviceTelegramCounters(self.store, node_id)
        if heartbeat_ms is not None and self.store.has(0x1017, 0):
            self.store.set(0x1017, 0, heartbeat_ms, notify=False)
            self.store.saved[(0x1017, 0)] = heartbeat_ms
        self.state = NmtState.BOOTUP
        self.powered = False
        self.sdo_servers: dict[int, SdoServer] = {}
        self.pdo = PdoEngine(self)
        # One request queue and worker per SDO channel: a device serves SDO1 and SDO2 independently (two masters).
        # SimpleQueue: a block download hands over a frame at a time, queue.Queue's Python locking cost more per frame.
        self._requests: queue.SimpleQueue[tuple[int, bytes, float] | None] = queue.SimpleQueue()
        self._requests2: queue.SimpleQueue[tuple[int, bytes, float] | None] = queue.SimpleQueue()
        self._worker: threading.Thread | None = None
        self._worker2: threading.Thread | None = None
        self._next_heartbeat = 0.0
        self.emcy_active: list[tuple[int, int, bytes]] = []
        self._guard_toggle = 0
        self.faults = FaultState()
        """SDO faults switched on for tests and demos (``node.faults.set(wrong_toggle=True)``)."""
        self.wake: Callable[[], None] = _no_wake
        """Tells the plant's ticker that something changed (set by the plant): it ticks at once, not at a timer."""
        self.store.add_write_hook(self._on_write)
        self.program = ProgramStore(self.store, self.faults, f"{self.name} firmware 1.0".encode(), self._power_cut)
        """CiA 302-3 program download objects (0x1F50 ... 0x1F57) in front of the store."""
        self._build_sdo_servers()
        self.drive = _device_control(self)
        """The drive model the profile names (CiA 402 inverter or servo, Lenze control/status words), if any."""

    # --- life cycle -------------------------------------------------------------------------------------
    def power_on(self) -> None:
        self.powered = True
        if self._worker is None:
            self._worker = threading.Thread(target=self._work, args=(self._requests,),
                                            name=f"sim-node-{self.node_id}", daemon=True)
            self._worker.start()
            self._worker2 = threading.Thread(target=self._work, args=(self._requests2,),
                                             name=f"sim-node-{self.node_id}-sdo2", daemon=True)
            self._worker2.start()
        self._boot()

    def power_off(self) -> None:
        self.powered = False
        self.pdo.stop()
        self._requests.put(None)
        self._requests2.put(None)
        for worker in (self._worker, self._worker2):
            if worker is not None:
                worker.join(timeout=2)
        self._worker = self._worker2 = None

    def _boot(self) -> None:
        self.state = NmtState.BOOTUP
        self._guard_toggle = 0
        self._build_sdo_servers()
        self.send(0x700 + self.node_id, bytes([NmtState.BOOTUP]))
        self.state = NmtState.PRE_OPERATIONAL
        if self.drive is not None:
            self.drive.reset()
        self._next_heartbeat = time.monotonic() + self.heartbeat_period_s() if self.heartbeat_period_s() else 0.0
        self.pdo.reconfigure()
        self.wake()

    def _power_cut(self, back_after_s: float = 0.3) -> None:
        """The power fails (a fault while flashing): silent at once, back after ``back_after_s`` with a boot-up."""
        self.powered = False
        self.pdo.stop()
        threading.Timer(back_after_s, self._power_back).start()

    def _power_back(self) -> None:
        self.powered = True
        self._boot()

    def send(self, cob_id: int, data: bytes) -> None:
        if self.powered:
            self._send(cob_id, data)
            self.telegram_counters.count(cob_id)

    # --- frames from the bus (dispatcher thread) --------------------------------------------------------
    def on_frame(self, cob_id: int, data: bytes, timestamp: float) -> None:
        if not self.powered:
            return
        self.telegram_counters.count(cob_id)
        if cob_id == 0x000:
            self._on_nmt(data)
            self.wake()  # a state change starts or stops the PDOs
        elif cob_id in self.sdo_servers:
            if self.state is not NmtState.STOPPED:
                # the frame's time on the bus travels with it: a busy dispatcher's or worker's backlog is no idle
                # client to the server (a frame without a timestamp is stamped on arrival, on the same clock)
                (self._requests if cob_id == 0x600 + self.node_id else self._requests2).put(
                    (cob_id, data, timestamp or time.time()))
        elif cob_id == 0x080 and self.state is NmtState.OPERATIONAL:
            self.pdo.on_sync()
        elif self.state is NmtState.OPERATIONAL:
            self.pdo.on_frame(cob_id, data)

    def _on_nmt(self, data: bytes) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        try:
            command = NmtCommand(data[0])
        except ValueError:
            return
        if command is NmtCommand.START:
            self.state = NmtState.OPERATIONAL
            self.pdo.on_operational()
        elif command is NmtCommand.STOP:
            self.state = NmtState.STOPPED
        elif command is NmtCommand.ENTER_PRE_OPERATIONAL:
            self.state = NmtState.PRE_OPERATIONAL
        elif command is NmtCommand.RESET_NODE:
            self.store.restore(self.store.saved)
            self._boot()
        elif command is NmtCommand.RESET_COMMUNICATION:
            self.store.restore(self.store.saved, communication_only=True)
            self._boot()

    # --- SDO --------------------------------------------------------------------------------------------
    def _build_sdo_servers(self) -> None:
        servers: dict[int, SdoServer] = {}
        channels = [(0x600 + self.node_id, 0x580 + self.node_id)]
        second = self._second_sdo_channel()
        if second:
            channels.append(second)
        features = self.profile.features
        for rx_cob, tx_cob in channels:
            servers[rx_cob] = SdoServer(self.node_id, self._answer_sdo(rx_cob), self.program, rx_cob=rx_cob,
                                        tx_cob=tx_cob, segmented=features.segmented_sdo, block=features.block_sdo,
                                        timeout_s=SDO_IDLE_S)
        self.sdo_servers = servers

    def _second_sdo_channel(self) -> tuple[int, int] | None:
        if not (self.store.has(0x1201, 1) and self.store.has(0x1201, 2)):
            return None
        rx, tx = self.store.get(0x1201, 1), self.store.get(0x1201, 2)
        if not isinstance(rx, int) or not isinstance(tx, int) or (rx | tx) & 0x80000000:
            return None
        return rx & 0x7FF, tx & 0x7FF

    def _answer_sdo(self, rx_cob: int) -> Send:
        def send(cob_id: int, data: bytes) -> None:
            answer = self.faults.on_answer(rx_cob, data)
            if answer is not None:
                self.send(cob_id, answer)

        return send

    def _faulty_request(self, server: SdoServer, data: bytes) -> bool:
        """True when an active fault takes the request (dropped, or aborted with the fault's code)."""
        if len(data) != 8:
            return False
        if server.expects_segment and data[0] != 0x80:
            # a block download segment starts with its sequence number (0x21 reads like an initiate download): no
            # transfer starts here, so only the latency every request has applies (and no lock per frame is taken)
            extra_s = self.faults.segment_delay_s()
            if extra_s:
                time.sleep(extra_s)
            return False
        extra_s = self.faults.delay_s(data)
        if extra_s:
            time.sleep(extra_s)
        verdict = self.faults.on_request(server.rx_cob, data)
        if verdict is None:
            return False
        if verdict:
            server.reset()
            self.send(server.tx_cob, b"\x80" + data[1:4] + verdict.to_bytes(4, "little"))
        return True

    def _work(self, requests: queue.SimpleQueue[tuple[int, bytes, float] | None]) -> None:
        while True:
            item = requests.get()
            if item is None:
                return
            cob_id, data, arrived = item
            server = self.sdo_servers.get(cob_id)
            if server is None:
                continue
            if self.latency.mean_s and not server.busy:
                time.sleep(self.latency.sample())  # the device's parameter data processing time
            try:
                if not self._faulty_request(server, data):
                    server.on_request(data, arrived)
            except Exception:  # a simulator bug must not kill the node
                log.exception("node %d: SDO request %s failed", self.node_id, data.hex())

    # --- behaviour of written objects -------------------------------------------------------------------
    def _on_write(self, index: int, sub: int, raw: RawValue) -> None:
        self.wake()
        if (index, sub) == (0x1017, 0):
            period = self.heartbeat_period_s()
            self._next_heartbeat = time.monotonic() + period if period else 0.0
        elif (index, sub) == (0x1003, 0):
            self._clear_error_history(raw)
        elif index in (0x1010, 0x1011) and sub:
            self._store_or_restore(index, sub, raw)
        elif index == 0x1201:
            self._build_sdo_servers()
        elif 0x1400 <= index <= 0x1BFF:
            self.pdo.reconfigure()
        self._device_command(index, sub, raw)

    def _store_or_restore(self, index: int, sub: int, raw: RawValue) -> None:
        """CiA 301 0x1010 'save' / 0x1011 'load' (defaults take effect at the next reset); any other value aborts."""
        if raw != (SAVE_SIGNATURE if index == 0x1010 else LOAD_SIGNATURE):
            self.store.set(index, sub, 1, notify=False)
            raise Abort(0x08000020)  # data cannot be transferred or stored to the application
        if index == 0x1010:
            self.store.saved = self.store.snapshot()
        else:
            self.store.saved = ObjectStore(self.profile, self.node_id).snapshot()

    def _device_command(self, index: int, sub: int, raw: RawValue) -> None:
        """Device commands of the code the profile's save command writes (8400: C00002, index 0x5FFD, 8400 motec
        CANopen manual: C00002/11 save all parameter sets, C00002/26 CAN reset node), each written as 1."""
        if (index, raw) != self._device_command_code or sub not in (DEVICE_COMMAND_SAVE, DEVICE_COMMAND_RESET_NODE):
            return
        if sub == DEVICE_COMMAND_SAVE:
            self.store.saved = self.store.snapshot()
        else:
            threading.Timer(0.01, self._on_nmt, args=(bytes([NmtCommand.RESET_NODE, self.node_id]),)).start()

    def on_remote_request(self, cob_id: int) -> None:
        """Node guarding (CiA 301): answer the master's remote frame with the state and an alternating toggle bit."""
        if not self.powered or cob_id != 0x700 + self.node_id or not self.profile.features.node_guarding:
            return
        if self.heartbeat_period_s():  # CiA 301: with a heartbeat producer time set, heartbeat is used instead
            return
        self.send(0x700 + self.node_id, bytes([(self._guard_toggle << 7) | self.state]))
        self._guard_toggle ^= 1

    # --- periodic work (plant timer thread) -------------------------------------------------------------
    def heartbeat_period_s(self) -> float:
        if not self.store.has(0x1017, 0):
            return 0.0
        raw = self.store.get(0x1017, 0)
        return float(raw) / 1000 if isinstance(raw, (int, float)) else 0.0

    def tick(self, now: float) -> float | None:
        """Do what is due at ``now``; returns when the node next needs a tick (heartbeat, drive cycle, TPDO timer),
        None if nothing is due until something changes (a frame or a write, which wakes the plant)."""
        if not self.powered:
            return None
        if self._next_heartbeat and now >= self._next_heartbeat:
            self.send(0x700 + self.node_id, bytes([self.state]))
            period = self.heartbeat_period_s()
            self._next_heartbeat = (self._next_heartbeat + period) if period else 0.0
            if self._next_heartbeat and self._next_heartbeat < now:
                self._next_heartbeat = now + period
        due: list[float | None] = [self._next_heartbeat or None]
        if self.drive is not None:
            self.drive.tick(now)
            next_tick = getattr(self.drive, "next_tick", None)  # a drive model naming no deadline: cycled as before
            due.append(next_tick() if next_tick is not None else now + UNTIMED_DRIVE_TICK_S)
        if self.state is NmtState.OPERATIONAL:
            due.append(self.pdo.tick(now))
        return min((at for at in due if at is not None), default=None)

    # --- EMCY -------------------------------------------------------------------------------------------
    def emcy_cob_id(self) -> int | None:
        if self.store.has(0x1014, 0):
            raw = self.store.get(0x1014, 0)
            if isinstance(raw, int):
                return None if raw & 0x80000000 else raw & 0x7FF
        return 0x80 + self.node_id

    def raise_emcy(self, code: int, register: int = 0x01, vendor: bytes = b"") -> None:
        """Send an emergency telegram and enter it in the error history 0x1003 and register 0x1001."""
        data = code.to_bytes(2, "little") + bytes([register]) + (vendor + bytes(5))[:5]
        self.emcy_active.append((code, register, vendor))
        if self.store.has(0x1001, 0):
            self.store.set(0x1001, 0, register, notify=False)
        self._push_error_history(code, vendor)
        cob = self.emcy_cob_id()
        if cob is not None and self.state is not NmtState.STOPPED:
            self.send(cob, data)

    def fault_bytes(self, number: int) -> bytes:
        """The five manufacturer-specific EMCY bytes carrying the device's fault number where its profile's
        ``faults.emcy_number`` puts it (else in the first four bytes)."""
        where = self.profile.faults.emcy_number if self.profile.faults else None
        start, length = (where.byte - 3, where.length) if where else (0, 4)
        data = bytearray(5)
        data[start:start + length] = (number & ((1 << 8 * length) - 1)).to_bytes(length, "little")
        return bytes(data)

    def record_fault(self, number: int) -> None:
        """The device's present-fault parameter (the first of its profile's ``faults.present``) holds ``number``."""
        present = self.profile.faults.present if self.profile.faults else []
        if present:
            with contextlib.suppress(KeyError, ValueError, UnknownParameter):
                self.store.set_ref(present[0], number)

    def clear_emcy(self) -> None:
        """All errors gone: the error-free EMCY (code 0x0000, register 0x00)."""
        self.emcy_active.clear()
        if self.store.has(0x1001, 0):
            self.store.set(0x1001, 0, 0, notify=False)
        cob = self.emcy_cob_id()
        if cob is not None and self.state is not NmtState.STOPPED:
            self.send(cob, bytes(8))

    def _clear_error_history(self, raw: RawValue) -> None:
        """CiA 301: writing 0 to 0x1003 sub 0 deletes the error history; any other value is refused."""
        entries = [sub for sub in range(1, 255) if self.store.has(0x1003, sub)]
        if raw != 0:
            self.store.set(0x1003, 0, sum(1 for sub in entries if self.store.get(0x1003, sub)), notify=False)
            raise Abort(0x06090030)
        for sub in entries:
            self.store.set(0x1003, sub, 0, notify=False)

    def _push_error_history(self, code: int, vendor: bytes) -> None:
        if not self.store.has(0x1003, 0):
            return
        entries = [sub for sub in range(1, 255) if self.store.has(0x1003, sub)]
        if not entries:
            return
        values = [self.store.get(0x1003, sub) for sub in entries]
        info = int.from_bytes((vendor + bytes(2))[:2], "little")
        values = [(info << 16) | code, *values[:-1]]
        for sub, value in zip(entries, values, strict=True):
            self.store.set(0x1003, sub, value, notify=False)
        count = self.store.get(0x1003, 0)
        self.store.set(0x1003, 0, min(int(count) + 1 if isinstance(count, int) else 1, len(entries)),
                       notify=False)
