"""The line project of plants/new-line.json that the wizard tests commission: four planned nodes (20-23) with the
identity their profiles state, the serial where the label tells it (the two Lenze devices share vendor and product,
so only their serials tell them apart), a parameter set per node and, for the servo, the firmware the line expects
(the CRC32 of :data:`AXIS_FIRMWARE`, which is what the simulated drive reports in 0x1F56 after the download)."""

from __future__ import annotations

import json
import sys
import zlib
from pathlib import Path
from typing import Any

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.line.store import expected_identity

AXIS_FIRMWARE = bytes(range(256)) * 8
"""A 2 KiB image: the program the project expects on the axis."""
AXIS_VERSION = f"0x{zlib.crc32(AXIS_FIRMWARE):08X}"

NODES: list[dict[str, Any]] = [
    {"node_id": 20, "name": "Conveyor", "profile": "lenze-8400-motec-canopen", "serial": 1001,
     "values": {"0x1017": 400}},
    {"node_id": 21, "name": "Fan", "profile": "lenze-8200-vector-emf2178ib", "serial": 2002,
     "values": {"0x100C": 20}},
    {"node_id": 22, "name": "Pump", "profile": "siemens-micromaster4-canopen", "serial": None,
     "values": {"0x100C": 30}},
    {"node_id": 23, "name": "Axis", "profile": "generic-cia402-servo", "serial": None,
     "values": {"0x6083": 5000, "0x6084": 4000}, "firmware": AXIS_VERSION},
]


def new_line_project(registry: ProfileRegistry) -> dict[str, Any]:
    nodes = []
    for planned in NODES:
        profile = registry.get(planned["profile"])
        identity = expected_identity(profile).model_dump(mode="json")
        if planned["serial"] is not None:
            identity["serial"] = f"0x{planned['serial']:08X}"
        nodes.append({"node_id": planned["node_id"], "name": planned["name"], "device": planned["profile"],
                      "baud_kbit": 500, "identity": identity, "profile": {"id": planned["profile"], "sha256": ""},
                      "parameter_set": {"name": f"{planned['name']} set", "values": dict(planned["values"])},
                      "firmware_version": planned.get("firmware")})
    return {"schema_version": 1, "name": "New line", "nodes": nodes}


def write_example(folder: Path) -> list[Path]:
    """The project file and the axis's firmware, for trying the wizard by hand (README "New line")."""
    folder.mkdir(parents=True, exist_ok=True)
    project, firmware = folder / "new-line-project.json", folder / "axis.bin"
    project.write_text(json.dumps(new_line_project(ProfileRegistry()), indent=2) + "\n", encoding="utf-8")
    firmware.write_bytes(AXIS_FIRMWARE)
    return [project, firmware]


if __name__ == "__main__":  # python -m tests.line_wizard_project <folder>
    for written in write_example(Path(sys.argv[1] if len(sys.argv) > 1 else ".")):
        print(written)
