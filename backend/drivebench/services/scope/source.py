"""What a scope recording reads from: its channels, the frames a source delivers and the interface of a source.

A source samples every channel of a recording on one time base. Sampling by PDO (free TPDOs of each node mapped
"synchronous every n SYNC", a SYNC producer at the chosen period) numbers its frames by SYNC count, so channels of
different nodes line up; the fallbacks (SDO polling on CAN, CoE polling on EtherCAT) number them by poll round and
report the rate they really reach.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

SourceKind = Literal["pdo", "sdo-poll", "coe-poll"]
EventKind = Literal["emcy", "nmt", "drive-state", "fault", "source"]


@dataclass(frozen=True)
class ScopeChannel:
    """One recorded value: a node's object, named as the parameters API names it (``C00051``, ``r0021``,
    ``0x606C.0``), optionally one bit of it (status-word bits)."""

    node: int
    ref: str
    bit: int | None = None


@dataclass(frozen=True)
class ScopeFrame:
    """One sample of every channel.

    ``sample``: the sample number on the common time base (SYNC count since the recording started for PDO
    sampling, the poll round for polling); ``time_s``: seconds since the start on that time base (``sample *
    period_s`` for PDO sampling); ``raw``: one raw value per channel in the recording's channel order, ``None`` where
    the channel's node sent nothing for this sample.
    """

    sample: int
    time_s: float
    raw: tuple[int | None, ...]


@dataclass(frozen=True)
class ScopeEvent:
    """A marker on the time axis: an EMCY, an NMT state change, a drive state change, a fault of the source itself
    (a node that stopped sending, SYNC lost, a TPDO remapped by someone else, bus-off) in words."""

    time_s: float
    node: int | None
    kind: EventKind
    text: str


FrameSink = Callable[[ScopeFrame], None]
EventSink = Callable[[ScopeEvent], None]


class ScopeSource(Protocol):
    """A running acquisition. ``start`` calls the sinks on the event loop (never from a bus thread); ``stop``
    restores everything the source changed on the nodes and returns what it restored and read back, in words."""

    kind: SourceKind
    period_s: float
    """The sample period the source really reaches (shown to the user as the rate)."""

    async def start(self, on_frame: FrameSink, on_event: EventSink) -> None: ...

    def elapsed_s(self) -> float:
        """Now, on the source's time base (seconds since its sample 0): where an event of the session (an EMCY, an
        NMT change) goes on the time axis."""
        ...

    async def stop(self) -> list[str]: ...
