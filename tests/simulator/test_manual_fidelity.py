"""Simulated drives answering as their manuals say (issue 20), read and written by canopen's SDO client over a
python-can virtual bus: abort codes, read-back values, Lenze parameter sets and array sub 0."""

from __future__ import annotations

from collections.abc import Iterator

import canopen
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.lenze_control import WordControl
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.conftest import wait_until
from tests.simulator.canopen_master import abort_code, remote

MM4, MOTEC, VECTOR = 3, 5, 12
P1203, P0918, C00349 = (0x24B3, 0), (0x2396, 0), (0x5FFF - 349, 0)
C00324_1 = (0x5FFF - 324, 1)  # 8400 "CAN Tx inhibit time", U16


NODES = {MM4: "siemens-micromaster4-canopen", MOTEC: "lenze-8400-motec-canopen", VECTOR: "lenze-8200-vector-emf2178ib"}


@pytest.fixture
def plant(registry: ProfileRegistry, channel: str) -> Iterator[Plant]:
    nodes = [PlantNode(node_id=node_id, profile=profile_id) for node_id, profile_id in NODES.items()]
    running = Plant(PlantFile(name="fidelity", bus=f"virtual:{channel}@500000", nodes=nodes), registry.get)
    try:
        yield running.start()
    finally:
        running.stop()


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


# --- 8200 vector parameter sets (EMF2178IB manual §10.2.1, §10.3, §9.3.1.1) --------------------------------------
def c_index(code: int) -> int:
    return 0x5FFF - code


def test_8200_parameter_set_2_at_0x5823_is_its_own_value(master: canopen.Network, plant: Plant) -> None:
    """§10.3 example: C0012 in parameter set 2 is index 24575 - 12 - 2000 = 0x5823; the four sets hold their own
    values (C0012, C2012, C4012, C6012)."""
    node = remote(master, VECTOR)
    assert c_index(2012) == 0x5823
    set_1 = node.sdo.upload(c_index(12), 0)
    for pset in (2, 3, 4):
        assert node.sdo.upload(c_index(12 + 2000 * (pset - 1)), 0) == set_1  # the same Lenze setting
    node.sdo.download(0x5823, 0, (20 * 10000).to_bytes(4, "little"))  # C2012 = 20 s (FIX32)
    assert int.from_bytes(node.sdo.upload(0x5823, 0), "little") == 200000
    assert node.sdo.upload(c_index(12), 0) == set_1
    assert node.sdo.upload(c_index(4012), 0) == set_1
    assert abort_code(lambda: node.sdo.upload(c_index(2046), 0)) == 0x06020000  # C0046 exists once only


def test_8200_control_word_changes_over_the_parameter_set(master: canopen.Network, plant: Plant) -> None:
    """AIF-CTRL (C0135) bit 12 DCTRL1-PAR2/4, bit 13 DCTRL1-PAR3/4; AIF-STAT (C0150) bit 0 DCTRL-PAR-B0. The drive
    then ramps with the active set's acceleration time (C0012 / C2012 ...)."""
    node, drive = remote(master, VECTOR), plant.nodes[VECTOR]
    control = drive.drive
    assert isinstance(control, WordControl)
    node.sdo.download(c_index(2012), 0, (1 * 10000).to_bytes(4, "little"))  # C2012 = 1 s, set 1 keeps its 5 s
    ramp_set_1 = control.ramp_per_s()

    def status_bit_0() -> int:
        return int.from_bytes(node.sdo.upload(c_index(150), 0), "little") & 1

    for bits, pset in ((0, 1), (1 << 12, 2), (1 << 13, 3), (3 << 12, 4)):
        node.sdo.download(c_index(135), 0, (bits | 1 << 9).to_bytes(2, "little"))  # + CINH
        assert control.parameter_set == pset
        assert wait_until(lambda expected=(pset - 1) & 1: status_bit_0() == expected)  # type: ignore[misc]
        if pset == 2:
            assert control.ramp_per_s() == pytest.approx(ramp_set_1 * 5)


# --- 8400 motec coded arrays: sub 0 (issue item 14) ----------------------------------------------------------------
@pytest.mark.parametrize(("index", "highest"), [(0x5A20, None), (0x5C93, 4), (0x5E9B, None), (0x5FFD, None)])
def test_motec_coded_array_sub_0_is_the_highest_subcode(master: canopen.Network, plant: Plant, index: int,
                                                        highest: int | None) -> None:
    """CiA 301: sub 0 of an array is 'highest sub-index supported' (U8, ro); the EDS declares it for the coded
    arrays, so the drive answers it with the highest subcode its profile lists."""
    subs = [sub for (i, sub) in plant.nodes[MOTEC].store.snapshot() if i == index and sub > 0]
    answer = remote(master, MOTEC).sdo.upload(index, 0)
    assert answer == bytes([max(subs)])
    if highest is not None:
        assert max(subs) == highest
