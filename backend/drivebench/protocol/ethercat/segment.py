"""The slaves behind one EtherCAT mailbox gateway: an SDO client per station address (SDO and SDO information),
their emergencies, and counters of the mailbox traffic (requests, responses, aborts, emergencies per slave)
for the monitor.

Answers are matched to requests by the station address in their mailbox header; one transfer at a time per slave
(:meth:`EthercatSegment.lock`), any number of slaves at once. Emergencies a slave puts into its mailbox arrive
between answers and go to the emergency listeners instead of being taken for an answer.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from drivebench.protocol.ethercat import coe, coe_info
from drivebench.protocol.ethercat.coe_sdo import DEFAULT_MAILBOX_SIZE, CoeSdoClient
from drivebench.transport.ethercat_gateway import GatewayLink, GatewaySpec

EmergencyListener = Callable[[int, int, int, bytes, float], None]
"""(station, error code, error register, 5 data bytes, time)."""


@dataclass
class MailboxCounters:
    requests: int = 0
    responses: int = 0
    aborts: int = 0
    emergencies: int = 0
    timeouts: int = 0


@dataclass
class _Slave:
    lock: threading.Lock = field(default_factory=threading.Lock)
    answers: queue.SimpleQueue[bytes] = field(default_factory=queue.SimpleQueue)
    counters: MailboxCounters = field(default_factory=MailboxCounters)
    client: CoeSdoClient | None = None


class EthercatSegment:
    def __init__(self, spec: GatewaySpec, *, timeout_s: float = 0.5, retries: int = 1,
                 mailbox_size: int = DEFAULT_MAILBOX_SIZE) -> None:
        self.spec = spec
        self.timeout_s = timeout_s
        self.retries = retries
        self.mailbox_size = mailbox_size
        self._slaves: dict[int, _Slave] = {}
        self._slaves_lock = threading.Lock()
        self._emergency_listeners: list[EmergencyListener] = []
        self.link = GatewayLink(spec, self._on_telegram)

    def _slave(self, station: int) -> _Slave:
        with self._slaves_lock:
            return self._slaves.setdefault(station, _Slave())

    def add_emergency_listener(self, listener: EmergencyListener) -> None:
        self._emergency_listeners.append(listener)

    def counters(self, station: int) -> MailboxCounters:
        return self._slave(station).counters

    def lock(self, station: int) -> threading.Lock:
        """Held around a transfer: a slave's mailbox serves one request at a time."""
        return self._slave(station).lock

    def sdo(self, station: int) -> CoeSdoClient:
        slave = self._slave(station)
        if slave.client is None:
            slave.client = CoeSdoClient(lambda telegram, timeout: self._exchange(station, telegram, timeout), station,
                                        mailbox_size=self.mailbox_size, timeout_s=self.timeout_s,
                                        retries=self.retries, receive=lambda timeout: self._receive(station, timeout))
        return slave.client

    def _exchange(self, station: int, telegram: bytes, timeout_s: float) -> bytes | None:
        slave = self._slave(station)
        while not slave.answers.empty():  # a late answer to an earlier try is not this one's
            slave.answers.get_nowait()
        slave.counters.requests += 1
        self.link.send(telegram)
        try:
            return slave.answers.get(timeout=timeout_s)
        except queue.Empty:
            slave.counters.timeouts += 1
            return None

    def _receive(self, station: int, timeout_s: float) -> bytes | None:
        """The slave's next telegram without a request (a further fragment of an SDO information response)."""
        try:
            return self._slave(station).answers.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def _on_telegram(self, telegram: bytes) -> None:
        mailbox = coe.Mailbox.decode(telegram)
        slave = self._slave(mailbox.address)
        if mailbox.type == coe.MailboxType.COE:
            message = coe.CoeMessage.decode(mailbox.data)
            if message.service == coe.CoeService.EMERGENCY:
                slave.counters.emergencies += 1
                code, register, data = coe.parse_emergency(message.body)
                now = time.time()
                for listener in self._emergency_listeners:
                    listener(mailbox.address, code, register, data, now)
                return
            if message.body[:1] == bytes([coe.ABORT]) or (
                    message.service == coe.CoeService.SDO_INFORMATION
                    and message.body[:1] == bytes([coe_info.InfoOpcode.ERROR_REQUEST])):
                slave.counters.aborts += 1
        slave.counters.responses += 1
        slave.answers.put(telegram)

    def close(self) -> None:
        self.link.close()
