"""The manuals' SDO telegrams, replayed against the simulated drives over a real python-can bus.

canopen's SDO client talks to the simulator; a second bus object records the wire and every frame is compared
byte for byte with the manual. Node ids and values are the manuals' (where an issue text names others, the
manual's example is the vector).
"""

from __future__ import annotations

import time

import can
import canopen
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.datatypes import decode
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.conftest import wait_until
from tests.vectors.manual_sdo import LENZE_8400, LENZE_EMF2178IB, MICROMASTER, SdoVector

PROFILE_BY_GROUP = [
    (LENZE_8400, "lenze-8400-motec-canopen"),
    (LENZE_EMF2178IB, "lenze-8200-vector-emf2178ib"),
    (MICROMASTER, "siemens-micromaster4-canopen"),
]
CASES = [pytest.param(vector, profile, id=vector.id) for group, profile in PROFILE_BY_GROUP for vector in group]


def _wire_frames(wire: can.BusABC, node: int) -> list[tuple[int, bytes]]:
    frames = []
    while (msg := wire.recv(0.05)) is not None:
        if msg.arbitration_id in (0x600 + node, 0x580 + node):
            frames.append((msg.arbitration_id, bytes(msg.data)))
    return frames


@pytest.mark.parametrize(("vector", "profile_id"), CASES)
def test_manual_telegram(vector: SdoVector, profile_id: str, registry: ProfileRegistry, channel: str,
                         wire: can.BusABC) -> None:
    plant_file = PlantFile(name="vector", bus=f"virtual:{channel}",
                           nodes=[PlantNode(node_id=vector.node, profile=profile_id, heartbeat_ms=0)])
    plant = Plant(plant_file, registry.get).start()
    network = canopen.Network().connect(interface="virtual", channel=channel)
    try:
        sim = plant.nodes[vector.node]
        slot = sim.store.slot(vector.index, vector.subindex)
        if vector.direction == "upload":
            sim.store.set(vector.index, vector.subindex, decode(slot.data_type, vector.value), notify=False)
        time.sleep(0.05)
        while wire.recv(0) is not None:  # drop the boot-up
            pass
        remote = network.add_node(vector.node, canopen.ObjectDictionary())
        # canopen waits 0.3 s by default and then sends the request again: on a loaded machine the simulated drive
        # can answer later than that, and a repeated request would add frames the manual's exchange does not have
        remote.sdo.RESPONSE_TIMEOUT = 10.0
        if vector.direction == "upload":
            assert remote.sdo.upload(vector.index, vector.subindex) == vector.value
        elif vector.request.data[0] & 0x03 == 0x02:
            # Expedited without size (MICROMASTER 0x22): canopen always indicates the size, so send the manual's
            # frame itself and wait for the drive to take it.
            network.send_message(vector.request.cob_id, vector.request.data)
            assert wait_until(lambda: sim.store.read(vector.index, vector.subindex) == vector.value, 5)
        else:
            remote.sdo.download(vector.index, vector.subindex, vector.value)
            # MICROMASTER P0918 is a word written with one byte (0x2F): the drive holds it as a word
            assert sim.store.read(vector.index, vector.subindex) == vector.value.ljust(slot.data_type.size or 0, b"\0")
        frames = _wire_frames(wire, vector.node)
        expected = [frame for exchange in vector.exchanges for frame in exchange]
        assert len(frames) == len(expected), [f"{c:03X} {d.hex(' ')}" for c, d in frames]
        for (cob_id, data), want in zip(frames, expected, strict=True):
            assert want.matches(cob_id, data), f"got 0x{cob_id:03X}: {data.hex(' ').upper()}, manual: {want}"
    finally:
        network.disconnect()
        plant.stop()
