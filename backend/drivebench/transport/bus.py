"""Open a CAN bus by python-can interface name, channel and bit rate.

A bus is written ``INTERFACE:CHANNEL@BITRATE`` (``socketcan:can0@500000``, ``pcan:PCAN_USBBUS1@250000``,
``virtual:plant@500000``) or, for socketcand gateways, ``socketcand:HOST:PORT/CHANNEL`` (``@BITRATE`` optional).
Any interface python-can knows is accepted; nothing here assumes the bus is local or virtual.
"""

from __future__ import annotations

import contextlib
import functools
import re
import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import can
from pydantic import BaseModel, Field, ValidationError

from drivebench.errors import AdapterUnavailable, BusSpecError, TransportError
from drivebench.i18n import N_, Text

DEFAULT_BITRATE = 500_000
_SOCKETCAND_RE = re.compile(r"^socketcand:(?P<host>[^:/@]+):(?P<port>\d+)/(?P<channel>[^@]+)(?:@(?P<bitrate>\d+))?$")
_GENERIC_RE = re.compile(r"^(?P<interface>[a-z_][a-z0-9_]*):(?P<channel>[^@]*)(?:@(?P<bitrate>\d+))?$")

# What to check when an adapter cannot be opened, per interface (the rest get the generic hint).
_HINTS = {
    "socketcan": N_("Is the interface up? Run 'ip link set {channel} up type can bitrate {bitrate}' (needs SocketCAN "
                    "in the kernel and root)."),
    "socketcand": N_("Is a socketcand gateway listening at {host}:{port}, and does it serve channel '{channel}'? "
                     "For a local test bus start 'drivebench hub --port {port}'."),
    "pcan": N_("Is the PEAK driver installed and the adapter plugged in? Channel names look like PCAN_USBBUS1."),
    "kvaser": N_("Is Kvaser CANlib installed and the adapter plugged in? Channels are numbers (0, 1 ...)."),
    "ixxat": N_("Is the IXXAT VCI driver installed and the adapter plugged in?"),
    "vector": N_("Is the Vector XL driver installed, and is the channel assigned to an application in Vector "
                 "Hardware Config?"),
    "slcan": N_("Is the serial port right (e.g. /dev/ttyACM0 or COM3) and not used by another program?"),
    "gs_usb": N_("Is the candleLight/gs_usb adapter plugged in and is pyusb installed?"),
}
_GENERIC_HINT = N_("Check that the adapter is plugged in, its driver is installed, and the channel name is right.")
CANNOT_OPEN = N_("Cannot open {bus}: {reason}")
ADAPTER_LOST = N_("adapter lost: {reason}")


HOST_CLOCK_INTERFACES = frozenset({"virtual", "socketcan"})
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})


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
            raise BusSpecError(Text(N_("'{text}' is not a bus specification. Write INTERFACE:CHANNEL@BITRATE "
                                        "(socketcan:can0@500000, pcan:PCAN_USBBUS1@250000) or "
                                        "socketcand:HOST:PORT/CHANNEL."), text=text))
        return cls.build(interface=match["interface"], channel=match["channel"],
                         bitrate=int(match["bitrate"] or DEFAULT_BITRATE))

    @classmethod
    def build(cls, **fields: Any) -> BusSpec:
        """Construct from user input: a value out of range is a BusSpecError, not a validation traceback."""
        try:
            return cls(**fields)
        except ValidationError as exc:
            problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
            raise BusSpecError(Text(N_("Invalid bus settings: {problems}"), problems=problems)) from exc

    def __str__(self) -> str:
        if self.interface == "socketcand":
            return (f"socketcand:{self.options.get('host')}:{self.options.get('port')}/{self.channel}"
                    f"@{self.bitrate}")
        return f"{self.interface}:{self.channel}@{self.bitrate}"

    def stamps_in_host_clock(self) -> bool:
        """Whether python-can stamps this bus's received frames in ``time.time()``'s clock of this host: the virtual
        bus and socketcan (the kernel's receive time) do, and a socketcand gateway on this host; an adapter's own
        clock (pcan, kvaser, vector, ixxat ... convert a hardware counter with an offset taken at start) or a
        gateway on another host is off by an unknown amount."""
        if self.interface == "socketcand":
            return str(self.options.get("host", "")) in LOOPBACK_HOSTS
        return self.interface in HOST_CLOCK_INTERFACES

    def hint(self) -> Text:
        """What to check when the adapter cannot be opened, in the reader's words (``str()`` where it is shown)."""
        return Text(_HINTS.get(self.interface, _GENERIC_HINT), channel=self.channel or "can0", bitrate=self.bitrate,
                     host=self.options.get("host", "?"), port=self.options.get("port", "?"))


def known_interfaces() -> list[str]:
    return sorted(can.interfaces.VALID_INTERFACES)


FrameObserver = Callable[[can.Message], None]
Opener = Callable[[], can.BusABC]
SendGuard = Callable[[], "str | None"]

RECONNECT_FIRST_S = 0.2
RECONNECT_MAX_S = 5.0
"""Back-off between attempts to reopen a lost adapter: doubling from the first to the longest delay."""


class AdapterLost(TransportError, can.CanOperationError):
    """The adapter stopped working (unplugged, driver error, gateway connection closed). Also a python-can
    error, so canopen's client and the protocol layer treat it like any adapter failure."""

    title = N_("CAN adapter lost")


class BusUnusable(TransportError, can.CanOperationError):
    """The adapter is there but must not send now (bus-off), or did not take a frame in time."""

    title = N_("CAN bus not usable")


@dataclass(frozen=True)
class LinkState:
    """Whether the adapter works; while it is lost, why, since when and how the reconnection goes."""

    lost_reason: str | None = None
    lost_at: float | None = None
    attempts: int = 0
    last_attempt_error: str | None = None
    reconnects: int = 0
    reconnected_at: float | None = None

    @property
    def lost(self) -> bool:
        return self.lost_reason is not None


class SimulatedAdapter:
    """The switches of a virtual bus's pretend adapter: pull its plug, make its controller report a state.

    A test or the demo drives them; the session sees what a real adapter would show (python-can raising
    ``CanOperationError`` on send and receive, ``BusABC.state`` passive or bus-off).

    The adapter also has a bit rate (python-can's virtual bus has none): a frame carries its sender's rate and only
    adapters at that rate receive it, as controllers at different rates do not hear each other on a wire.
    ``every_rate`` makes an adapter hear frames at every rate and send each at the rate the frame names
    (:class:`RatedFrame`): the simulated plant's, whose devices each keep their own rate.
    """

    def __init__(self) -> None:
        self.unplugged: str | None = None
        self.state = can.BusState.ACTIVE
        self.every_rate = False

    def unplug(self, reason: str | None = None) -> None:
        self.unplugged = reason or Text(N_("USB adapter unplugged"))  # worded when shown, in the reader's language

    def plug_in(self) -> None:
        self.unplugged = None

    def report(self, state: can.BusState) -> None:
        self.state = state


class RatedFrame(can.Message):
    """A frame with the bit rate it went over a virtual bus at (``None``: not known, e.g. from a plain python-can
    bus on the same channel: every adapter hears it)."""

    __slots__ = ("bitrate",)
    bitrate: int | None

    @classmethod
    def at(cls, bitrate: int | None, **fields: Any) -> RatedFrame:
        frame = cls(**fields)
        frame.bitrate = bitrate
        return frame


def rate_of(msg: can.Message) -> int | None:
    """The bit rate a frame was sent at, if it is known."""
    return getattr(msg, "bitrate", None)


class _VirtualFrame(RatedFrame):
    """A frame as handed to python-can's virtual bus, which copies it for every other bus on the channel with
    ``deepcopy``: copying its data (a bytearray) that way costs several times a whole new message (a program download
    sends some 38,000 frames, benchmarks/RESULTS.md). The receivers get a :class:`RatedFrame`: its sender's rate."""

    __slots__ = ()

    @classmethod
    def of(cls, msg: can.Message, bitrate: int | None) -> _VirtualFrame:
        frame = cls(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                    is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame, channel=msg.channel,
                    dlc=msg.dlc, data=msg.data, is_fd=msg.is_fd, is_rx=msg.is_rx, bitrate_switch=msg.bitrate_switch,
                    error_state_indicator=msg.error_state_indicator)
        frame.bitrate = bitrate
        return frame

    def __deepcopy__(self, memo: dict[int, Any] | None) -> can.Message:
        return RatedFrame.at(self.bitrate, timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                             is_extended_id=self.is_extended_id, is_remote_frame=self.is_remote_frame,
                             is_error_frame=self.is_error_frame, channel=self.channel, dlc=self.dlc,
                             data=bytearray(self.data), is_fd=self.is_fd, is_rx=self.is_rx,
                             bitrate_switch=self.bitrate_switch, error_state_indicator=self.error_state_indicator)


class _SwitchedBus(can.BusABC):
    """A real python-can bus behind a :class:`SimulatedAdapter`. Unplugged: send and receive raise. Bus-off: the
    controller is off the bus, nothing is sent or received."""

    def __init__(self, inner: can.BusABC, adapter: SimulatedAdapter, rate: int) -> None:
        self.inner = inner
        self.adapter = adapter
        self.rate = rate
        """The bit rate this adapter was opened at: it hears frames sent at that rate only."""
        self.channel_info = inner.channel_info
        super().__init__(channel=getattr(inner, "channel", "") or "")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.adapter.unplugged:
            raise can.CanOperationError(self.adapter.unplugged)
        if self.adapter.state is not can.BusState.ERROR:
            rate = (rate_of(msg) or self.rate) if self.adapter.every_rate else self.rate
            self.inner.send(_VirtualFrame.of(msg, rate), timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.adapter.unplugged:
            raise can.CanOperationError(self.adapter.unplugged)
        msg = self.inner.recv(timeout)
        if self.adapter.state is can.BusState.ERROR:
            return None, False
        if msg is not None and not self.adapter.every_rate and rate_of(msg) not in (None, self.rate):
            return None, False  # sent at another bit rate: this controller does not hear it (BusABC.recv waits on)
        return msg, False

    @property
    def state(self) -> can.BusState:
        return self.adapter.state

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self.adapter.state = new_state

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()
        self.inner.shutdown()


class ObservedBus(can.BusABC):
    """Wraps an opened python-can bus so every transmitted frame is also seen by observers (the monitor), and
    keeps working when the adapter does not.

    Periodic sends use BusABC's software tasks, which call :meth:`send`, so they are observed too.

    When the adapter fails (python-can raises on send or receive, a socketcand gateway closes the connection)
    the bus is *lost*: sends fail at once with :class:`AdapterLost`, receiving waits quietly (the notifier thread
    lives on), and a thread reopens the adapter with back-off; the reopened adapter replaces the old one under
    the same object, so the canopen network and every listener carry on. ``send_guard`` (set by the session)
    names a reason to refuse sending, e.g. bus-off, so requests fail at once instead of timing out one by one.
    """

    def __init__(self, inner: can.BusABC, spec: BusSpec, *, reopen: Opener | None = None,
                 adapter: SimulatedAdapter | None = None) -> None:
        self.inner = inner
        self.spec = spec
        self.adapter = adapter
        self.channel_info = f"{spec}"
        self.send_guard: SendGuard | None = None
        self.link = LinkState()
        self._reopen = reopen
        self._observers: list[FrameObserver] = []
        self._link_watchers: list[Callable[[LinkState], None]] = []
        self._lock = threading.Lock()
        self._restored = threading.Event()
        self._restored.set()
        self._wake = threading.Event()
        self._closing = threading.Event()
        self._reconnector: threading.Thread | None = None
        self._retired: can.BusABC | None = None
        """The adapter closed by :meth:`reopen_at`: its errors are not a lost adapter."""
        super().__init__(channel=spec.channel or "")

    def add_observer(self, observer: FrameObserver) -> None:
        with self._lock:
            self._observers = [*self._observers, observer]

    def remove_observer(self, observer: FrameObserver) -> None:
        with self._lock:
            self._observers = [o for o in self._observers if o is not observer]

    def watch_link(self, watcher: Callable[[LinkState], None]) -> None:
        """``watcher(link)`` runs (on the thread that noticed) when the adapter is lost and when it is back."""
        self._link_watchers.append(watcher)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        link = self.link
        if link.lost_reason is not None:
            raise AdapterLost(Text(ADAPTER_LOST, reason=link.lost_reason), hint=self._lost_hint())
        guard = self.send_guard
        refusal = guard() if guard is not None else None
        if refusal:
            raise BusUnusable(refusal)
        inner = self.inner
        try:
            inner.send(msg, timeout)
        except can.CanTimeoutError as exc:  # transmit queue full: the adapter is there, the bus does not take it
            raise BusUnusable(Text(N_("the adapter did not send the frame in time: {reason}"), reason=exc)) from exc
        except (can.CanError, OSError, ValueError) as exc:
            reason = self._lose(inner, exc)
            raise AdapterLost(Text(ADAPTER_LOST, reason=reason), hint=self._lost_hint()) from exc
        if not msg.timestamp:
            msg.timestamp = time.time()
        for observer in self._observers:
            observer(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.link.lost_reason is not None:
            self._restored.wait(1.0 if timeout is None else timeout)
            return None, False
        inner = self.inner
        try:
            msg = inner.recv(timeout)
        except (can.CanError, OSError, ValueError) as exc:
            self._lose(inner, exc)
            return None, False
        if msg is None and _peer_closed(inner):
            self._lose(inner, Text(N_("the socketcand gateway closed the connection")))  # worded when shown
        return msg, False

    # --- another bit rate ---------------------------------------------------------------------------------
    def reopen_at(self, bitrate: int) -> None:
        """Close the adapter and open it again at ``bitrate`` (python-can's ``bitrate=``, the way each interface
        that sets its controller's rate takes it); the canopen network and every listener carry on under the same
        object, and a later reconnection uses the new rate. When the adapter does not open at the new rate it is
        opened at the old one again and the error raised; when that fails too, it is lost (and retried)."""
        old_spec = self.spec
        spec = old_spec.model_copy(update={"bitrate": bitrate})
        with self._lock:
            retired = self._retired = self.inner
        with contextlib.suppress(Exception):  # one adapter may not be opened twice (pcan): close it first
            retired.shutdown()
        try:
            fresh = _open_adapter(spec, self.adapter)
        except TransportError as exc:
            try:
                self._take(_open_adapter(old_spec, self.adapter), old_spec)
            except TransportError:
                self._retired = None
                self._lose(retired, exc)
            raise
        self._take(fresh, spec)

    def _take(self, fresh: can.BusABC, spec: BusSpec) -> None:
        with self._lock:
            self.inner, self.spec, self.channel_info = fresh, spec, f"{spec}"
            self._reopen = functools.partial(_open_adapter, spec, self.adapter)
            self._retired = None

    # --- adapter lost and back ----------------------------------------------------------------------------
    def _lost_hint(self) -> Text:
        return Text(N_("The session reconnects by itself when the adapter is back. {hint}"), hint=self.spec.hint())

    def _lose(self, inner: can.BusABC, cause: BaseException | str) -> str:
        """Mark the adapter lost (once per adapter) and start reconnecting; returns the reason."""
        if isinstance(cause, str):
            reason = cause
        elif cause.args and isinstance(cause.args[0], Text):
            reason = cause.args[0]  # the simulated adapter's reason: worded when shown
        else:
            reason = str(cause).splitlines()[0] if str(cause) else type(cause).__name__
        with self._lock:
            if inner is not self.inner or inner is self._retired or self.link.lost or self._closing.is_set():
                return self.link.lost_reason or reason
            self.link = replace(self.link, lost_reason=reason, lost_at=time.time(), attempts=0,
                                last_attempt_error=None)
            self._restored.clear()
        with contextlib.suppress(Exception):  # a dead adapter may fail to close too; its queue must not grow
            inner.shutdown()
        self._tell_watchers()
        if self._reopen is not None:
            self._reconnector = threading.Thread(target=self._reconnect_loop, name=f"reconnect-{self.spec}",
                                                 daemon=True)
            self._reconnector.start()
        return reason

    def reconnect_now(self) -> None:
        """Try to reopen the lost adapter now instead of after the back-off delay."""
        self._wake.set()

    def _reconnect_loop(self) -> None:
        assert self._reopen is not None
        delay = RECONNECT_FIRST_S
        while True:
            self._wake.wait(delay)
            self._wake.clear()
            if self._closing.is_set():
                return
            try:
                fresh = self._reopen()
            except Exception as exc:  # vendor drivers raise anything; keep trying
                self.link = replace(self.link, attempts=self.link.attempts + 1,
                                    last_attempt_error=getattr(exc, "detail", None) or str(exc))
                delay = min(delay * 2, RECONNECT_MAX_S)
                continue
            with self._lock:
                if self._closing.is_set():
                    fresh.shutdown()
                    return
                self.inner = fresh
                self.link = LinkState(reconnects=self.link.reconnects + 1, reconnected_at=time.time())
                self._restored.set()
            self._tell_watchers()
            return

    def _tell_watchers(self) -> None:
        link = self.link
        for watcher in list(self._link_watchers):
            with contextlib.suppress(Exception):
                watcher(link)

    @property
    def state(self) -> can.BusState:
        return self.inner.state

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self.inner.state = new_state

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        self._closing.set()
        self._wake.set()
        self._restored.set()
        super().shutdown()
        with contextlib.suppress(Exception):
            self.inner.shutdown()
        if self._reconnector is not None and self._reconnector is not threading.current_thread():
            self._reconnector.join(timeout=RECONNECT_MAX_S)


def _peer_closed(inner: can.BusABC) -> bool:
    """Whether a socketcand client's gateway closed the TCP connection: python-can's client then reads nothing,
    forever, instead of raising."""
    sock = getattr(inner, "_SocketCanDaemonBus__socket", None)
    if not isinstance(sock, socket.socket):
        return False
    try:
        readable, _, _ = select.select([sock], [], [], 0)
        return bool(readable) and sock.recv(1, socket.MSG_PEEK) == b""
    except (OSError, ValueError):
        return True


def open_bus(spec: BusSpec) -> ObservedBus:
    """Open the adapter. Every failure becomes a TransportError naming the interface and what to check.

    A virtual bus gets a :class:`SimulatedAdapter` (``bus.adapter``) whose plug and controller state can be
    switched at run time."""
    adapter = SimulatedAdapter() if spec.interface == "virtual" else None
    opener = functools.partial(_open_adapter, spec, adapter)
    return ObservedBus(opener(), spec, reopen=opener, adapter=adapter)


def _open_adapter(spec: BusSpec, adapter: SimulatedAdapter | None = None) -> can.BusABC:
    if spec.interface not in can.interfaces.VALID_INTERFACES:
        raise AdapterUnavailable(
            Text(N_("Unknown CAN interface '{interface}'."), interface=spec.interface),
            hint=Text(N_("python-can knows: {interfaces}."), interfaces=", ".join(known_interfaces())))
    if adapter is not None and adapter.unplugged:
        raise AdapterUnavailable(Text(CANNOT_OPEN, bus=spec, reason=adapter.unplugged), hint=spec.hint())
    kwargs: dict[str, Any] = {"interface": spec.interface, "channel": spec.channel or None,
                              "bitrate": spec.bitrate, **spec.options}
    if spec.interface == "virtual":
        kwargs["receive_own_messages"] = False
    if spec.interface == "socketcand":
        _probe_gateway(spec)
        # python-can's low-latency option: TCP_NODELAY and TCP_QUICKACK, so an SDO request or answer on the
        # gateway's TCP connection never waits for Nagle's algorithm or a delayed ACK (benchmarks/RESULTS.md).
        kwargs.setdefault("tcp_tune", True)
    try:
        inner = can.Bus(**kwargs)
    except Exception as exc:  # vendor drivers raise anything (kvaser without CANlib: NameError)
        reason = str(exc) or type(exc).__name__
        raise AdapterUnavailable(Text(CANNOT_OPEN, bus=spec, reason=reason), hint=spec.hint()) from exc
    return _SwitchedBus(inner, adapter, spec.bitrate) if adapter is not None else inner


def _probe_gateway(spec: BusSpec, timeout_s: float = 2.0) -> None:
    """python-can's socketcand client retries for 10 s and prints every attempt: ask once, quickly."""
    host, port = spec.options.get("host"), spec.options.get("port")
    if not host or not port:
        raise BusSpecError(Text(N_("A socketcand bus needs host and port: socketcand:HOST:PORT/CHANNEL")))
    try:
        with socket.create_connection((str(host), int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise AdapterUnavailable(Text(N_("Cannot reach the socketcand gateway at {host}:{port}: {reason}"),
                                       host=host, port=port, reason=exc), hint=spec.hint()) from exc
