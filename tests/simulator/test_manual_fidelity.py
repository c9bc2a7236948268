"""Simulated drives answering as their manuals say (issue 20), read and written by canopen's SDO client over a
python-can virtual bus: abort codes, read-back values, Lenze parameter sets and array sub 0."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drivebench.device.loader import ProfileRegistry
from drivebench.simulator.plant import Plant, PlantFile, PlantNode

MM4, MOTEC, VECTOR = 3, 5, 12
P1203, P0918, C00349 = (0x24B3, 0), (0x2396, 0), (0x5FFF - 349, 0)
C00324_1 = (0x5FFF - 324, 1)  # 8400 "CAN Tx inhibit time", U16


@pytest.fixture
def plant(registry: ProfileRegistry, channel: str) -> Iterator[Plant]:
    plant_file = PlantFile(name="fidelity", bus=f"virtual:{channel}@500000", nodes=[
        PlantNode(node_id=MM4, profile="siemens-micromaster4-canopen"),
        PlantNode(node_id=MOTEC, profile="lenze-8400-motec-canopen"),
        PlantNode(node_id=VECTOR, profile="lenze-8200-vector-emf2178ib")])
    running = Plant(plant_file, registry.get).start()
    yield running
    running.stop()


@pytest.fixture
def master(channel: str, plant: Plant) -> Iterator[canopen.Network]:
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel, receive_own_messages=False)
    yield network
    network.disconnect()


def remote(master: canopen.Network, node_id: int) -> canopen.RemoteNode:
    node = canopen.RemoteNode(node_id, canopen.ObjectDictionary())
    master.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 2.0
    return node


def abort_code(action: Callable[[], object]) -> int:
    with pytest.raises(SdoAbortedError) as caught:
        action()
    return int(caught.value.code)


def test_mm4_double_word_to_a_word_parameter_is_0x06070010(master: canopen.Network, plant: Plant) -> None:
    """MICROMASTER §3.2.4 abort table: 06070010H 'Mixture between word and double word'; it lists no 0607 0012."""
    node = remote(master, MM4)
    assert abort_code(lambda: node.sdo.download(*P1203, (99).to_bytes(4, "little"))) == 0x06070010  # 0x23
    assert abort_code(lambda: node.sdo.download(0x25DD, 0, (12).to_bytes(2, "little"))) == 0x06070010  # U32 P1501
    node.sdo.download(*P1203, (99).to_bytes(2, "little"))  # the manual's example 2, a word: taken
    assert plant.nodes[MM4].store.get(*P1203) == 99


def test_mm4_p0918_is_a_word_the_traced_byte_write_is_taken(master: canopen.Network, plant: Plant) -> None:
    """Object table: P0918 U16; ch. 5.7.2 trace writes it with 0x2F (1 byte), which the drive accepts."""
    node = remote(master, MM4)
    assert node.sdo.upload(*P0918) == (3).to_bytes(2, "little")
    node.sdo.download(*P0918, b"\x04")
    assert node.sdo.upload(*P0918) == (4).to_bytes(2, "little")


def test_lenze_keeps_the_cia_301_length_aborts(master: canopen.Network) -> None:
    node = remote(master, MOTEC)
    assert abort_code(lambda: node.sdo.download(*C00324_1, (5).to_bytes(4, "little"))) == 0x06070012
    assert abort_code(lambda: node.sdo.download(*C00324_1, b"\x05")) == 0x06070013


def test_motec_c00349_reads_accept_dip_switch_at_24v_on(master: canopen.Network) -> None:
    """§12.2 C00349 bit 15 'Accept DIP switch at 24V-ON': the switches (all OFF) were read at switch-on."""
    assert int.from_bytes(remote(master, MOTEC).sdo.upload(*C00349), "little") == 0x8000
