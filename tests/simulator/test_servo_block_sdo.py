"""The generic CiA 402 servo serves SDO block upload and download, like the other simulated drives that state it.

Driven by canopen's SDO client (``block_transfer=True``) on a python-can virtual bus.
"""

from __future__ import annotations

from collections.abc import Iterator

import canopen
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.simulator.canopen_master import remote

SERVO = 7
PROFILE_VELOCITY = (0x6081, 0)


@pytest.fixture
def plant(registry: ProfileRegistry, channel: str) -> Iterator[Plant]:
    plant_file = PlantFile(name="servo block SDO", bus=f"virtual:{channel}@500000",
                           nodes=[PlantNode(node_id=SERVO, profile="generic-cia402-servo")])
    running = Plant(plant_file, registry.get).start()
    yield running
    running.stop()


def test_servo_profile_states_block_transfer(registry: ProfileRegistry) -> None:
    assert registry.get("generic-cia402-servo").features.block_sdo


def test_block_upload_of_the_device_name(master: canopen.Network) -> None:
    with remote(master, SERVO).sdo.open(0x1008, 0, "rb", block_transfer=True) as stream:
        assert stream.read() == b"Generic CiA 402 servo"


def test_block_download_then_block_upload(master: canopen.Network, plant: Plant) -> None:
    node = remote(master, SERVO)
    payload = (1234).to_bytes(4, "little")
    with node.sdo.open(*PROFILE_VELOCITY, "wb", size=len(payload), block_transfer=True) as stream:
        stream.write(payload)
    assert plant.nodes[SERVO].store.get(*PROFILE_VELOCITY) == 1234
    with node.sdo.open(*PROFILE_VELOCITY, "rb", block_transfer=True) as stream:
        assert stream.read() == payload
