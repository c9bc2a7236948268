"""Every readable entry of every shipped EDS, read from the simulated plant by an independent CANopen master.

The master is canopen's RemoteNode with the shipped EDS as its object dictionary, on a python-can virtual bus;
nothing of DriveBench's own protocol layer is involved. A profile and its simulated drive that disagree (an entry
the EDS declares but the drive aborts) fail here, so the two cannot drift apart again.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import ODArray, ODRecord, ODVariable
from canopen.sdo.exceptions import SdoAbortedError

from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.simulator.canopen_master import connected

NODE_ID = 9


def hostable() -> list[Path]:
    """The shipped EDS files of CAN devices (an EtherCAT unit is offline-only: the plant speaks CAN)."""
    registry = ProfileRegistry()
    return [path for path in sorted((settings.profiles_dir / "eds").glob("*.eds"))
            if registry.get(path.stem).features.transport == "canopen"]


SHIPPED = hostable()


def readable(od: canopen.ObjectDictionary) -> list[ODVariable]:
    variables: list[ODVariable] = []
    for obj in od.values():
        members = obj.values() if isinstance(obj, (ODRecord, ODArray)) else [obj]
        variables += [v for v in members if "r" in v.access_type]
    return variables


@pytest.fixture
def master(channel: str) -> Iterator[canopen.Network]:
    with connected(channel) as network:
        yield network


@pytest.mark.parametrize("eds", SHIPPED, ids=[path.stem for path in SHIPPED])
def test_every_readable_eds_entry_reads_without_abort(eds: Path, channel: str, master: canopen.Network,
                                                      registry: ProfileRegistry) -> None:
    plant = Plant(PlantFile(name="eds read-back", bus=f"virtual:{channel}@500000",
                            nodes=[PlantNode(node_id=NODE_ID, profile=eds.stem)]), registry.get).start()
    try:
        node = canopen.RemoteNode(NODE_ID, str(eds))
        master.add_node(node)
        node.sdo.RESPONSE_TIMEOUT = 2.0
        variables = readable(node.object_dictionary)
        assert len(variables) > 100
        aborted = {}
        for var in variables:
            try:
                node.sdo.upload(var.index, var.subindex)
            except SdoAbortedError as exc:
                aborted[f"0x{var.index:04X}sub{var.subindex} {var.name}"] = f"0x{exc.code:08X}"
        assert aborted == {}, "\n".join(f"{k}: {v}" for k, v in aborted.items())
    finally:
        plant.stop()
