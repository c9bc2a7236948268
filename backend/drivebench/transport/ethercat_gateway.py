"""The UDP link to an EtherCAT mailbox gateway (ETG.8200), as EtherCAT masters offer it (TwinCAT, the IgH master,
acontis, EtherCrab): one mailbox telegram per datagram to UDP port 0x88A4 (34980), behind a 2-byte EtherCAT frame
header of type 5 (mailbox) whose 11-bit length is the telegram's. The gateway routes a request to the slave whose
configured station address stands in the telegram's mailbox header and sends the slave's answer back.

A bus spec ``ethercat-mbg:HOST[:PORT]`` names a gateway. This module moves telegrams; what they say is the
protocol layer's (:mod:`drivebench.protocol.ethercat.coe`).
"""

from __future__ import annotations

import contextlib
import re
import socket
import struct
import threading
from collections.abc import Callable
from dataclasses import dataclass

from drivebench.errors import BusSpecError, TransportError
from drivebench.i18n import N_, Text

GATEWAY_PORT = 0x88A4
ETHERCAT_TYPE_MAILBOX = 5
MAILBOX_HEADER_SIZE = 6
MAX_DATAGRAM = 1500
GATEWAY_FAILED = N_("Mailbox gateway {bus}: {reason}")
NOTHING_LISTENS = N_("nothing listens on the gateway's UDP port")
_SPEC_RE = re.compile(r"^ethercat-mbg:(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\s]+)(?::(?P<port>\d{1,5}))?$")

TelegramHandler = Callable[[bytes], None]


class GatewayFormatError(ValueError):
    """A datagram that is not an EtherCAT mailbox frame; the text says why."""


@dataclass(frozen=True)
class GatewaySpec:
    host: str
    port: int = GATEWAY_PORT

    interface = "ethercat-mbg"
    bitrate = 100_000_000
    """EtherCAT's 100 Mbit/s (what a session shows where a CAN bus has its bit rate)."""

    @property
    def channel(self) -> str:
        return f"{self.host}:{self.port}"

    @classmethod
    def parse(cls, text: str) -> GatewaySpec:
        match = _SPEC_RE.match(text.strip())
        if not match:
            raise BusSpecError(Text(N_("'{text}' is not a mailbox gateway: write ethercat-mbg:HOST or "
                                        "ethercat-mbg:HOST:PORT (the gateway's UDP port, {port} by default)."),
                                     text=text, port=GATEWAY_PORT))
        port = int(match["port"] or GATEWAY_PORT)
        if not 1 <= port <= 65535:
            raise BusSpecError(Text(N_("'{text}': UDP port {port} is not between 1 and 65535."), text=text, port=port))
        return cls(match["host"].strip("[]"), port)

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ethercat-mbg:{host}:{self.port}"


def gateway_frame(telegram: bytes) -> bytes:
    if len(telegram) > 0x7FF:
        raise GatewayFormatError(f"a telegram of {len(telegram)} bytes does not fit an EtherCAT frame (2047)")
    return struct.pack("<H", len(telegram) | ETHERCAT_TYPE_MAILBOX << 12) + telegram


def telegram_of(datagram: bytes) -> bytes:
    """The mailbox telegram in a gateway datagram (bytes after it are ignored, as gateways do)."""
    if len(datagram) < 2 + MAILBOX_HEADER_SIZE:
        raise GatewayFormatError(f"a datagram of {len(datagram)} bytes holds no mailbox telegram")
    (header,) = struct.unpack_from("<H", datagram)
    if header >> 12 != ETHERCAT_TYPE_MAILBOX:
        raise GatewayFormatError(f"EtherCAT frame type {header >> 12}, not 5 (mailbox)")
    length = header & 0x7FF
    if length > len(datagram) - 2:
        raise GatewayFormatError(f"the frame header says {length} bytes, the datagram holds {len(datagram) - 2}")
    telegram = datagram[2:2 + length]
    (mailbox_length,) = struct.unpack_from("<H", telegram)
    if MAILBOX_HEADER_SIZE + mailbox_length > len(telegram):
        raise GatewayFormatError(f"the mailbox header says {mailbox_length} bytes follow, "
                                 f"{len(telegram) - MAILBOX_HEADER_SIZE} do")
    return bytes(telegram[:MAILBOX_HEADER_SIZE + mailbox_length])


class GatewayLink:
    """A UDP socket connected to one gateway and a thread that hands every telegram it answers to ``handler``.

    ``unreachable`` is set when the gateway's host says nothing listens on the port (ICMP port unreachable); it is
    cleared by the next datagram that arrives. Malformed datagrams are counted and dropped.
    """

    def __init__(self, spec: GatewaySpec, handler: TelegramHandler) -> None:
        self.spec = spec
        self.handler = handler
        self.malformed = 0
        self.sent = 0
        self.received = 0
        self.unreachable: str | None = None
        try:
            family = socket.AF_INET6 if ":" in spec.host else socket.AF_INET
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
            self._sock.connect((spec.host, spec.port))
        except OSError as exc:
            raise TransportError(Text(GATEWAY_FAILED, bus=spec, reason=exc.strerror or exc),
                                 hint=N_("Check the gateway's address and that its master has the mailbox gateway "
                                         "switched on (UDP port 34980).")) from exc
        self._closed = threading.Event()
        self._reader = threading.Thread(target=self._read, name=f"mbg-{spec.host}:{spec.port}", daemon=True)
        self._reader.start()

    def send(self, telegram: bytes) -> None:
        if self._closed.is_set():
            raise TransportError(Text(GATEWAY_FAILED, bus=self.spec, reason=Text(N_("the link is closed."))))
        try:
            self._sock.send(gateway_frame(telegram))
        except ConnectionRefusedError:
            self.unreachable = NOTHING_LISTENS
        except OSError as exc:
            raise TransportError(Text(GATEWAY_FAILED, bus=self.spec, reason=Text(
                N_("sending failed: {reason}"), reason=exc.strerror or exc))) from exc
        self.sent += 1

    def _read(self) -> None:
        while not self._closed.is_set():
            try:
                datagram = self._sock.recv(MAX_DATAGRAM)
            except ConnectionRefusedError:
                self.unreachable = NOTHING_LISTENS
                continue
            except OSError:
                if self._closed.is_set():
                    return
                continue
            self.unreachable = None
            try:
                telegram = telegram_of(datagram)
            except GatewayFormatError:
                self.malformed += 1
                continue
            self.received += 1
            with contextlib.suppress(Exception):  # a handler's fault must not end the reader
                self.handler(telegram)

    def close(self) -> None:
        self._closed.set()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
        self._reader.join(timeout=2)
