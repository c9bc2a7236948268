"""Telegram counters a simulated drive keeps itself, where its profile has them (8400 motec / BaseLine C: C00360),
so the monitor's side-by-side comparison compares with something that moves.

Each counter counts the frames of the COB-IDs its subcode name stands for (see
``device.telegram_counters.cob_ids_for``): frames the node sends, and frames on the bus it receives. Like the
drive, in 16 bits that wrap, from power-up (the values are not saved).
"""

from __future__ import annotations

from drivebench.device.profiles.telegram_counters import counted_cob_ids, counter_parameters
from drivebench.simulator.store import ObjectStore

WRAP = 1 << 16


class DeviceTelegramCounters:
    def __init__(self, store: ObjectStore, node_id: int) -> None:
        self._store = store
        self._by_cob_id: dict[int, list[tuple[int, int]]] = {}
        for item in counter_parameters(store.catalog):
            for cob_id in counted_cob_ids(item, node_id) or []:
                self._by_cob_id.setdefault(cob_id, []).append((item.index, item.subindex))

    def count(self, cob_id: int) -> None:
        for index, sub in self._by_cob_id.get(cob_id, ()):
            value = self._store.get(index, sub)
            self._store.set(index, sub, (int(value) + 1) % WRAP if isinstance(value, int) else 1, notify=False)
