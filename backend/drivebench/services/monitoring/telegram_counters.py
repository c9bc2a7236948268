"""The device's own telegram counters beside the monitor's counts (which parameters count what:
:mod:`drivebench.device.profiles.telegram_counters`). The device counts since power-up in 16 bits and wraps, the monitor
since its reset: the comparable figures are the increases between two reads, so each read also reports the
increase on both sides since the previous read.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Protocol

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.telegram_counters import cob_ids_for, counter_label, counter_parameters
from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import Monitor

WRAP = 1 << 16


def counter_items(session: Session, node_id: int) -> list[Item]:
    """The profile's telegram counter parameters of a node (reserved subcodes left out)."""
    catalog = session.node(node_id).catalog
    return counter_parameters(catalog) if catalog is not None else []


@dataclass
class _Previous:
    at: float
    device: dict[str, int]
    monitor: dict[str, int]


class CounterHistory:
    """The last read of each node's counters in a session, for the increases since then (the session's part)."""

    def __init__(self) -> None:
        self.previous: dict[int, _Previous] = {}

    def close(self) -> None:
        self.previous.clear()


class CounterHistoryPart(Protocol):
    """The session's services container as this module sees it (:meth:`Session.opened_services`)."""

    @property
    def counter_history(self) -> CounterHistory: ...


def history(session: Session) -> CounterHistory:
    services: CounterHistoryPart = session.opened_services()
    return services.counter_history


async def compare(session: Session, monitor: Monitor, node_id: int) -> dict[str, Any]:
    """Read the node's telegram counters via SDO and put them beside the monitor's counts."""
    items = counter_items(session, node_id)
    if not items:
        node = session.node(node_id)
        raise NotFound(_("The profile of node {node} ({device}) has no telegram counters").format(
            node=node_id, device=node.device_name))
    client = session.client(node_id)
    device: dict[str, int] = {}
    for item in items:
        raw = await client.aupload(item.index, item.subindex)
        device[item.ref] = int.from_bytes(raw[:2], "little")
    # The monitor's counts after the reads, so both include the read requests themselves up to the last answer.
    mapping = {item.ref: cob_ids_for(counter_label(item), node_id) for item in items}
    counted = {ref: monitor.counts_for(cobs) for ref, cobs in mapping.items() if cobs is not None}
    now = time.time()
    seen = history(session).previous
    previous = seen.get(node_id)
    seen[node_id] = _Previous(now, device, counted)
    rows = []
    for item in items:
        label = counter_label(item)
        cobs = mapping[item.ref]
        row: dict[str, Any] = {
            "ref": item.ref, "label": label, "device": device[item.ref],
            "cob_ids": [f"0x{c:03X}" for c in cobs] if cobs else [],
            "monitor": counted.get(item.ref), "monitor_wrapped": counted[item.ref] % WRAP
            if item.ref in counted else None, "device_increase": None, "monitor_increase": None}
        if previous is not None and item.ref in previous.device:
            row["device_increase"] = (device[item.ref] - previous.device[item.ref]) % WRAP
            if item.ref in counted and item.ref in previous.monitor:
                row["monitor_increase"] = counted[item.ref] - previous.monitor[item.ref]
        rows.append(row)
    return {"node": node_id, "time": now, "previous_time": previous.at if previous else None, "rows": rows}
