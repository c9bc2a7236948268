"""The seam between a session and its bus: what every fieldbus offers (:class:`Fieldbus`) and what one has that
another has not (:class:`Capabilities`).

Services ask ``network.capabilities.X`` (may I send NMT, is there a heartbeat, are there frames by identifier ...),
never the network's class. What only some buses have is reached through the capability:
:func:`~drivebench.protocol.canopen.network.frames_of` (frames by identifier: NMT, PDOs, SYNC, listeners; a bus
without them refuses in words, :data:`NO_FRAMES`) and :func:`~drivebench.protocol.ethercat.network.master_of` (a
master's slave list, AL states and mailbox counters).
Which class opens a bus specification is :data:`drivebench.protocol.bus_kinds.BUS_KINDS`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, TypeVar

from drivebench.i18n import N_
from drivebench.protocol.emcy import EmcyMonitor

ClientT_co = TypeVar("ClientT_co", covariant=True)
NO_FRAMES = N_("EtherCAT has no CAN identifiers: NMT, SYNC, PDO frames and node guarding do not exist on {bus}")


@dataclass(frozen=True)
class Capabilities:
    """What a bus has, as the services branch on it."""

    nmt: bool
    """NMT commands on the wire (CiA 301); without, a state change is the bus's own (:attr:`esm`)."""
    esm: bool
    """A master's slave list and state machine (EtherCAT AL states, read and requested)."""
    heartbeat: bool
    """Heartbeat producers and consumers (0x1016/0x1017) the tool listens to."""
    guarding: bool
    """Node guarding (remote frames)."""
    frames: bool
    """Frames by identifier: PDOs and SYNC sent as frames, frame listeners (monitor, trace), bus-off health."""
    mailbox_counters: bool
    """Telegram counters per node (mailbox requests, answers, aborts, emergencies) instead of frames."""
    second_sdo_channel: bool
    """A node may offer a second SDO channel (SDO2 on CAN; an EtherCAT slave has one mailbox)."""


CAN_BUS = Capabilities(nmt=True, esm=False, heartbeat=True, guarding=True, frames=True, mailbox_counters=False,
                       second_sdo_channel=True)
ETHERCAT = Capabilities(nmt=False, esm=True, heartbeat=False, guarding=False, frames=False, mailbox_counters=True,
                        second_sdo_channel=False)


class Fieldbus(Protocol[ClientT_co]):
    """What a session holds: SDO clients per node (the same methods and errors on every bus), the node list, the
    emergencies, and in words what the bus has (:attr:`capabilities`)."""

    capabilities: Capabilities
    sdo_timeout_s: float
    sdo_retries: int
    emcy: EmcyMonitor

    @property
    def spec(self) -> object:
        """The bus specification the network was opened with (shown in its texts)."""
        ...

    @property
    def nodes(self) -> Mapping[int, ClientT_co]: ...

    def node(self, node_id: int, abort_texts: Mapping[int, str] | None = None) -> ClientT_co: ...

    def scan(self, timeout_s: float = 0.5) -> list[int]: ...

    def sdo_label(self, node_id: int) -> str:
        """How the node's SDOs travel, for the Parameters tab (in the reader's language)."""
        ...

    def close(self) -> None: ...


class EventLoopTransfers:
    """``aupload``/``adownload`` for callers in the event loop: the blocking ``upload``/``download`` of the
    subclass (a CAN node's, an EtherCAT slave's) in a worker thread."""

    def upload(self, index: int, sub: int, *, block: bool = False, channel: int | None = None,
               urgent: bool = False) -> bytes:
        raise NotImplementedError

    def download(self, index: int, sub: int, data: bytes, *, block: bool = False,
                 channel: int | None = None, urgent: bool = False) -> None:
        raise NotImplementedError

    async def aupload(self, index: int, sub: int, **kwargs: object) -> bytes:
        return await asyncio.to_thread(self.upload, index, sub, **kwargs)  # type: ignore[arg-type]

    async def adownload(self, index: int, sub: int, data: bytes, **kwargs: object) -> None:
        await asyncio.to_thread(self.download, index, sub, data, **kwargs)  # type: ignore[arg-type]
