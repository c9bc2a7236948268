"""LSS slaves written from CiA 305 alone for the master's tests (no code shared with DriveBench's simulator): a
group of devices on one python-can bus; identical answers of several devices leave as one frame, as on a CAN bus.

Each device keeps its LSS address, its state (waiting/configuration), active and pending node ID and bit timing,
the selective-switch and identify progress, and its fastscan position. A node ID activated by switch state global
(waiting) is announced with a boot-up telegram (0x700 + id, 0x00), as CiA 301 initialisation ends.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import dataclass, field

import can

from drivebench.transport.bus import BusSpec, open_bus

NONE_ID = 0xFF
TABLE_0 = {0: 1_000_000, 1: 800_000, 2: 500_000, 3: 250_000, 4: 125_000, 6: 50_000, 7: 20_000, 8: 10_000}
"""CiA 305 bit timing table 0 (index 5 reserved)."""


@dataclass
class Cia305Device:
    vendor: int
    product: int
    revision: int
    serial: int
    node_id: int = NONE_ID
    configuring: bool = False
    pending: int = NONE_ID
    timing: int = 2
    stored: tuple[int, int] | None = None
    rate: int | None = None
    """The bit rate its controller runs at (None: the group's plain bus)."""
    _sel: list[int] = field(default_factory=list)
    _ident: list[int] = field(default_factory=list)
    _lss_pos: int = 0

    @property
    def ident(self) -> list[int]:
        return [self.vendor, self.product, self.revision, self.serial]

    def handle(self, frame: bytes) -> tuple[bytes | None, int | None]:
        """(answer or None, node id to boot with or None)."""
        op = frame[0]
        word = struct.unpack_from("<I", frame, 1)[0]
        if op == 0x04:
            started = None
            if frame[1] == 0 and self.configuring and self.node_id == NONE_ID and self.pending != NONE_ID:
                self.node_id = started = self.pending
            self.configuring = frame[1] == 1
            self._sel = []
            return None, started
        if 0x40 <= op <= 0x43:
            if self.configuring:
                return None, None
            self._sel = [*self._sel, word] if len(self._sel) == op - 0x40 else []
            if self._sel == self.ident:
                self.configuring, self._sel = True, []
                return b"\x44" + bytes(7), None
            return None, None
        if 0x46 <= op <= 0x4B:
            self._ident = [*self._ident, word] if len(self._ident) == op - 0x46 else ([word] if op == 0x46 else [])
            if len(self._ident) == 6:
                v, p, rl, rh, sl, sh = self._ident
                hit = v == self.vendor and p == self.product and rl <= self.revision <= rh and sl <= self.serial <= sh
                return (b"\x4f" + bytes(7) if hit else None), None
            return None, None
        if op == 0x4C:
            return (b"\x50" + bytes(7) if self.node_id == NONE_ID and self.pending == NONE_ID else None), None
        if op == 0x51:
            return self._fastscan(word, frame[5], frame[6], frame[7]), None
        if not self.configuring:
            return None, None
        if op == 0x11:
            ok = (frame[1] <= 127 and frame[1] != 0) or frame[1] == NONE_ID
            if ok:
                self.pending = frame[1]
            return bytes([0x11, 0 if ok else 1]) + bytes(6), None
        if op == 0x13:
            ok = frame[1] == 0 and frame[2] in (0, 1, 2, 3, 4, 6, 7, 8)
            if ok:
                self.timing = frame[2]
            return bytes([0x13, 0 if ok else 1]) + bytes(6), None
        if op == 0x17:
            self.stored = (self.pending, self.timing)
            return b"\x17\x00" + bytes(6), None
        if 0x5A <= op <= 0x5D:
            return bytes([op]) + struct.pack("<I", self.ident[op - 0x5A]) + bytes(3), None
        if op == 0x5E:
            return bytes([0x5E, self.node_id]) + bytes(6), None
        return None, None

    def _fastscan(self, id_number: int, bit_check: int, sub: int, nxt: int) -> bytes | None:
        if self.configuring or self.node_id != NONE_ID or self.pending != NONE_ID:
            return None
        if bit_check == 0x80:
            self._lss_pos = 0
            return b"\x4f" + bytes(7)
        if sub != self._lss_pos or bit_check > 31:
            return None
        if (id_number >> bit_check) != (self.ident[sub] >> bit_check):
            return None
        if bit_check == 0:
            self._lss_pos = nxt
            if nxt < sub:  # CiA 305: lss_next below lss_sub ends the scan
                self.configuring, self._lss_pos = True, 0
        return b"\x4f" + bytes(7)


class _AtRate(can.Listener):
    def __init__(self, group: Cia305Bus, rate: int | None) -> None:
        self.group, self.rate = group, rate

    def on_message_received(self, msg: can.Message) -> None:
        self.group.heard(msg, self.rate)


class Cia305Bus:
    """The devices on one virtual channel: each request goes to all; each distinct answer is sent once.

    With ``bitrate`` the devices' controllers run at that rate (simulated adapters of DriveBench's transport: each
    hears frames at its rate only); activate bit timing (0x15) moves a device in configuration state, after the
    switch delay, to the rate it was configured to (configure bit timing, or ``timing`` given)."""

    def __init__(self, channel: str, devices: list[Cia305Device], *, answer_delay_s: float = 0.0,
                 bitrate: int | None = None) -> None:
        self.channel = channel
        self.devices = devices
        self.answer_delay_s = answer_delay_s
        self.answers_sent = 0
        self._lock = threading.Lock()
        self.buses: dict[int | None, can.BusABC] = {}
        self.notifiers: list[can.Notifier] = []
        for device in devices:
            device.rate = bitrate
        self.bus = self._controller(bitrate)

    def _controller(self, rate: int | None) -> can.BusABC:
        if rate not in self.buses:
            bus = (can.Bus(interface="virtual", channel=self.channel) if rate is None
                   else open_bus(BusSpec(interface="virtual", channel=self.channel, bitrate=rate)))
            self.buses[rate] = bus
            self.notifiers.append(can.Notifier(bus, [_AtRate(self, rate)]))
        return self.buses[rate]

    def _move(self, device: Cia305Device, rate: int) -> None:
        with self._lock:
            self._controller(rate)
            device.rate = rate

    def heard(self, msg: can.Message, rate: int | None) -> None:
        if msg.arbitration_id != 0x7E5 or msg.is_remote_frame:
            return
        frame = (bytes(msg.data) + bytes(8))[:8]
        answers: list[bytes] = []
        boots: list[int] = []
        with self._lock:
            here = [device for device in self.devices if device.rate == rate]
            if frame[0] == 0x15 and rate is not None:
                delay_s = struct.unpack_from("<H", frame, 1)[0] / 1000
                for device in here:
                    if device.configuring and TABLE_0[device.timing] != rate:
                        threading.Timer(delay_s, self._move, (device, TABLE_0[device.timing])).start()
                return
            for device in here:
                answer, boot = device.handle(frame)
                if answer is not None and answer not in answers:
                    answers.append(answer)
                if boot is not None:
                    boots.append(boot)
        if answers and self.answer_delay_s:
            time.sleep(self.answer_delay_s)
        bus = self.buses[rate]
        for answer in answers:
            self.answers_sent += 1
            bus.send(can.Message(arbitration_id=0x7E4, data=answer, is_extended_id=False))
        for node_id in boots:
            bus.send(can.Message(arbitration_id=0x700 + node_id, data=b"\x00", is_extended_id=False))

    def shutdown(self) -> None:
        for notifier in self.notifiers:
            notifier.stop()
        for bus in self.buses.values():
            bus.shutdown()
