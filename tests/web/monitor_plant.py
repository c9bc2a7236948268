"""A small Lenze-only plant for the monitor's web tests (fast heartbeats keep the counters moving)."""

from __future__ import annotations

import json
from pathlib import Path

SESSION_ID = "monitor-plant"
PLANT = {
    "name": "Monitor plant",
    "bus": "virtual:unused@500000",
    "nodes": [
        {"node_id": 5, "profile": "lenze-8400-motec-canopen", "name": "Conveyor (8400 motec)",
         "heartbeat_ms": 100, "values": {"C00061": 43}},
        {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib", "name": "Fan (8200 vector)", "heartbeat_ms": 200},
    ],
}


def write_plant(directory: Path) -> Path:
    path = directory / "monitor-plant.json"
    path.write_text(json.dumps(PLANT), encoding="utf-8")
    return path
