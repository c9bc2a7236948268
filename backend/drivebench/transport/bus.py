"""Open a CAN bus by python-can interface name, channel and bit rate.

A bus is written ``INTERFACE:CHANNEL@BITRATE`` (``socketcan:can0@500000``, ``pcan:PCAN_USBBUS1@250000``,
``virtual:plant@500000``) or, for socketcand gateways, ``socketcand:HOST:PORT/CHANNEL`` (``@BITRATE`` optional).
Any interface python-can knows is accepted; nothing here assumes the bus is local or virtual.
"""

from __future__ import annotations

import re
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import can
from pydantic import BaseModel, Field, ValidationError

from drivebench.errors import AdapterUnavailable, BusSpecError

DEFAULT_BITRATE = 500_000
_SOCKETCAND_RE = re.compile(r"^socketcand:(?P<host>[^:/@]+):(?P<port>\d+)/(?P<channel>[^@]+)(?:@(?P<bitrate>\d+))?$")
_GENERIC_RE = re.compile(r"^(?P<interface>[a-z_][a-z0-9_]*):(?P<channel>[^@]*)(?:@(?P<bitrate>\d+))?$")

# What to check when an adapter cannot be opened, per interface (the rest get the generic hint).
_HINTS = {
    "socketcan": "Is the interface up? Run 'ip link set {channel} up type can bitrate {bitrate}' (needs SocketCAN in "
                 "the kernel and root).",
    "socketcand": "Is a socketcand gateway listening at {host}:{port}, and does it serve channel '{channel}'? "
                  "For a local test bus start 'drivebench hub --port {port}'.",
    "pcan": "Is the PEAK driver installed and the adapter plugged in? Channel names look like PCAN_USBBUS1.",
    "kvaser": "Is Kvaser CANlib installed and the adapter plugged in? Channels are numbers (0, 1 ...).",
    "ixxat": "Is the IXXAT VCI driver installed and the adapter plugged in?",
    "vector": "Is the Vector XL driver installed, and is the channel assigned to an application in Vector Hardware "
              "Config?",
    "slcan": "Is the serial port right (e.g. /dev/ttyACM0 or COM3) and not used by another program?",
    "gs_usb": "Is the candleLight/gs_usb adapter plugged in and is pyusb installed?",
}


class BusSpec(BaseModel):
    """Where a session's bus is: python-can interface, channel, bit rate, plus interface options."""

    interface: str = Field(min_length=1)
    channel: str = ""
    bitrate: int = Field(DEFAULT_BITRATE, gt=0, le=1_000_000)
    options: dict[str, Any] = Field(default_factory=dict)

    @classmethod
    def parse(cls, text: str) -> BusSpec:
        cleaned = text.strip()
        match = _SOCKETCAND_RE.match(cleaned)
        if match:
            return cls.build(interface="socketcand", channel=match["channel"],
                             bitrate=int(match["bitrate"] or DEFAULT_BITRATE),
                             options={"host": match["host"], "port": int(match["port"])})
        match = _GENERIC_RE.match(cleaned)
        if not match:
            raise BusSpecError(
                f"'{text}' is not a bus specification. Write INTERFACE:CHANNEL@BITRATE "
                "(socketcan:can0@500000, pcan:PCAN_USBBUS1@250000) or socketcand:HOST:PORT/CHANNEL.")
        return cls.build(interface=match["interface"], channel=match["channel"],
                         bitrate=int(match["bitrate"] or DEFAULT_BITRATE))

    @classmethod
    def build(cls, **fields: Any) -> BusSpec:
        """Construct from user input: a value out of range is a BusSpecError, not a validation traceback."""
        try:
            return cls(**fields)
        except ValidationError as exc:
            problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
            raise BusSpecError(f"Invalid bus settings: {problems}") from exc

    def __str__(self) -> str:
        if self.interface == "socketcand":
            return (f"socketcand:{self.options.get('host')}:{self.options.get('port')}/{self.channel}"
                    f"@{self.bitrate}")
        return f"{self.interface}:{self.channel}@{self.bitrate}"

    def hint(self) -> str:
        template = _HINTS.get(self.interface, "Check that the adapter is plugged in, its driver is installed, and "
                                              "the channel name is right.")
        return template.format(channel=self.channel or "can0", bitrate=self.bitrate,
                               host=self.options.get("host", "?"), port=self.options.get("port", "?"))


def known_interfaces() -> list[str]:
    return sorted(can.interfaces.VALID_INTERFACES)


FrameObserver = Callable[[can.Message], None]


class ObservedBus(can.BusABC):
    """Wraps an opened python-can bus so every transmitted frame is also seen by observers (the monitor).

    Periodic sends use BusABC's software tasks, which call :meth:`send`, so they are observed too.
    """

    def __init__(self, inner: can.BusABC, spec: BusSpec) -> None:
        self.inner = inner
        self.spec = spec
        self.channel_info = f"{spec}"
        self._observers: list[FrameObserver] = []
        self._lock = threading.Lock()
        super().__init__(channel=spec.channel or "")

    def add_observer(self, observer: FrameObserver) -> None:
        with self._lock:
            self._observers = [*self._observers, observer]

    def remove_observer(self, observer: FrameObserver) -> None:
        with self._lock:
            self._observers = [o for o in self._observers if o is not observer]

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)
        if not msg.timestamp:
            msg.timestamp = time.time()
        for observer in self._observers:
            observer(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self.inner.recv(timeout), False

    @property
    def state(self) -> can.BusState:
        return self.inner.state

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self.inner.state = new_state

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()
        self.inner.shutdown()


def open_bus(spec: BusSpec) -> ObservedBus:
    """Open the adapter. Every failure becomes a TransportError naming the interface and what to check."""
    if spec.interface not in can.interfaces.VALID_INTERFACES:
        raise AdapterUnavailable(
            f"Unknown CAN interface '{spec.interface}'.",
            hint=f"python-can knows: {', '.join(known_interfaces())}.")
    kwargs: dict[str, Any] = {"interface": spec.interface, "channel": spec.channel or None,
                              "bitrate": spec.bitrate, **spec.options}
    if spec.interface == "virtual":
        kwargs["receive_own_messages"] = False
    if spec.interface == "socketcand":
        _probe_gateway(spec)
    try:
        inner = can.Bus(**kwargs)
    except Exception as exc:  # vendor drivers raise anything (kvaser without CANlib: NameError)
        reason = str(exc) or type(exc).__name__
        raise AdapterUnavailable(f"Cannot open {spec}: {reason}", hint=spec.hint()) from exc
    return ObservedBus(inner, spec)


def _probe_gateway(spec: BusSpec, timeout_s: float = 2.0) -> None:
    """python-can's socketcand client retries for 10 s and prints every attempt: ask once, quickly."""
    host, port = spec.options.get("host"), spec.options.get("port")
    if not host or not port:
        raise BusSpecError("A socketcand bus needs host and port: socketcand:HOST:PORT/CHANNEL")
    try:
        with socket.create_connection((str(host), int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise AdapterUnavailable(f"Cannot reach the socketcand gateway at {host}:{port}: {exc}",
                                 hint=spec.hint()) from exc
