"""Apply / read-back round trips of PDO mappings against the simulated drives of every shipped CANopen profile
(8400 motec, 8200 vector + EMF2178IB, 93XX + EMF2178IB, MICROMASTER 440), with the objects each profile marks
PDO-mappable; and a mapping the device refuses mid-sequence leaves the PDO disabled."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest

from drivebench.device.profiles import pdo_notes
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.bus.sessions import Session
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import Direction, PdoWrite
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from drivebench.simulator.store import Abort
from tests.conftest import fresh_channel
from tests.write_contexts import SERVICE

NODES = {3: "siemens-micromaster4-canopen", 5: "lenze-8400-motec-canopen", 12: "lenze-8200-vector-emf2178ib",
         20: "lenze-93xx-emf2178ib"}
# node, direction, number, entries (index, sub) - each from the profile's PDO-mappable objects
ROUND_TRIPS: list[tuple[int, Direction, int, list[tuple[int, int]]]] = [
    (3, "rpdo", 5, [(0x6040, 0), (0x6042, 0), (0x2802, 3), (0x6060, 0)]),  # 7 bytes, in the P2041 sequence
    (3, "tpdo", 6, [(0x6041, 0), (0x6043, 0), (0x6077, 0), (0x6061, 0)]),
    (5, "rpdo", 2, [(0x5C9D, 5), (0x5C9D, 6), (0x5C9D, 7), (0x5C9D, 8)]),  # C00866/5...8: CAN2_IN words
    (5, "tpdo", 1, [(0x5C9B, 1), (0x5C9B, 2)]),  # C00868/1...2: CAN1_OUT words
    (12, "rpdo", 1, [(0x58E1, 3), (0x58E1, 1)]),  # AIF-IN words, reordered
    (12, "tpdo", 1, [(0x58E0, 2), (0x58E0, 1), (0x58E0, 3)]),
    (20, "rpdo", 1, [(0x58E1, 1), (0x58DF, 2), (0x58E1, 4)]),  # word + double word 2 + word = 8 bytes
    (20, "tpdo", 1, [(0x58DE, 3), (0x58E0, 1)]),
]


@pytest.fixture(scope="module")
def loop() -> Iterator[asyncio.AbstractEventLoop]:
    event_loop = asyncio.new_event_loop()
    yield event_loop
    event_loop.close()


@pytest.fixture(scope="module")
def drives(loop: asyncio.AbstractEventLoop) -> Iterator[tuple[Session, Plant]]:
    registry = ProfileRegistry()
    channel = fresh_channel()
    plant = Plant(PlantFile(name="pdo-profiles", bus=f"virtual:{channel}@500000",
                            nodes=[PlantNode(node_id=n, profile=p, heartbeat_ms=0) for n, p in NODES.items()]),
                  registry.get, latency="0ms").start()
    manager = SessionManager(registry)
    session = loop.run_until_complete(manager.open(f"virtual:{channel}@500000", name="pdo-profiles"))
    for node_id, profile_id in NODES.items():
        session.add_node(node_id, profile_id)
    yield session, plant
    loop.run_until_complete(manager.close_all())
    plant.stop()


def test_defaults_as_the_manuals_list_them(drives: tuple[Session, Plant], loop: asyncio.AbstractEventLoop) -> None:
    """Read from the simulated drives before any mapping changes (this test runs first in the module).

    MICROMASTER (ch. 5.4, table 6.1): only PDO 1, 5, 6; PDO1 fixed (0x6040 / 0x6041); PDO5/6 on the DS301 COB-IDs of
    PDO2/3, not mapped. 8400 motec (ch. 8.1, 8.3, 8.4): 2 RPDOs + 2 TPDOs on the CANopen base IDs (C00353 = 1, Lenze
    setting), type 254 (C00322/C00323), RPDO monitoring 3000 ms (C00357) with response 0 No reaction (C00593).
    EMF2178IB (ch. 4): three PDOs per direction on the predefined connection set."""
    session, _ = drives

    def table(node_id: int) -> list[tuple[str, int, int, bool, list[str]]]:
        configs = loop.run_until_complete(pdo.read_pdos(session, node_id))
        return [(c.direction, c.number, c.cob_id - node_id, c.fixed_mapping, [e.ref for e in c.entries])
                for c in configs]

    assert table(3) == [("rpdo", 1, 0x200, True, ["0x6040"]), ("rpdo", 5, 0x300, False, []),
                        ("rpdo", 6, 0x400, False, []), ("tpdo", 1, 0x180, True, ["0x6041"]),
                        ("tpdo", 5, 0x280, False, []), ("tpdo", 6, 0x380, False, [])]
    mm_tpdo5 = loop.run_until_complete(pdo.read_pdo(session, 3, "tpdo", 5))
    assert [s.ref for s in mm_tpdo5.settings] == ["P2041", "P2041.2"], "P2041.00 (TPDO5 type) and .02 (PDO5 mapping)"
    assert "Transmission type also set by P2041.00 high byte." in mm_tpdo5.notes
    motec = loop.run_until_complete(pdo.read_pdos(session, 5))
    assert [(c.direction, c.number, c.cob_id - 5, c.transmission_type) for c in motec] == [
        ("rpdo", 1, 0x200, 254), ("rpdo", 2, 0x300, 254), ("tpdo", 1, 0x180, 254), ("tpdo", 2, 0x280, 254)]
    # I-1600...I-1A01 default 0 (count 0, no entries): the static mapping of the port's 4 words (ch. 8.1)
    assert [[e.ref for e in c.entries] for c in motec] == [
        [f"C0086{6 if c.direction == 'rpdo' else 8}/{4 * (c.number - 1) + w}" for w in range(1, 5)] for c in motec]
    assert all(c.static_mapping and c.length_bytes == 8 for c in motec)
    assert not any(c.static_mapping for c in loop.run_until_complete(pdo.read_pdos(session, 12)))
    rpdo2 = {s.ref: s.value for s in motec[1].settings}
    assert rpdo2 == {"C00353/2": "1 = COBID = C0350 + CANBaseID", "C00357/2": "3000 ms", "C00593/2": "0 = No Reaction"}
    emf = loop.run_until_complete(pdo.read_pdos(session, 12))
    assert [(c.direction, c.number, c.cob_id - 12) for c in emf] == [
        ("rpdo", 1, 0x200), ("rpdo", 2, 0x300), ("rpdo", 3, 0x400),
        ("tpdo", 1, 0x180), ("tpdo", 2, 0x280), ("tpdo", 3, 0x380)]
    assert "depending on the basic device (§9.1)" in emf[1].notes[0] and not emf[0].notes
    assert emf[0].transmission_type == 254 and emf[0].transmission_note is None
    profile = session.node(12).profile
    assert profile is not None
    assert "0 ... 240, 254" in (pdo_notes.transmission_note(profile, "rpdo", 255) or "")


def test_p2041_bytes_of_the_manuals_examples(registry: ProfileRegistry) -> None:
    """MICROMASTER ch. 5.6 (table 5-1 examples, MM440): RPDO5 control word + target torque = 0x11, TPDO5 actual
    torque + modes display = 0x50; RPDO6 control word, per-unit speed, torque, modes = 0xD3; TPDO6 status word,
    actual torque, actual speed (rpm), modes display = 0x71 (the profile's pdo_rules.mapping_bits)."""
    rules = registry.get("siemens-micromaster4-canopen").pdo_rules
    assert rules is not None
    rpdo, tpdo = (rules.bits_for(direction, 5) for direction in ("rpdo", "tpdo"))
    assert rpdo is not None and tpdo is not None
    assert pdo_notes.selecting_byte(rpdo[0], [(0x6040, 0), (0x6071, 0)]) == 0x11
    assert pdo_notes.selecting_byte(tpdo[0], [(0x6077, 0), (0x6061, 0)]) == 0x50
    assert pdo_notes.selecting_byte(rpdo[0], [(0x6040, 0), (0x6052, 0), (0x6071, 0), (0x6060, 0)]) == 0xD3
    assert pdo_notes.selecting_byte(tpdo[0], [(0x6041, 0), (0x6077, 0), (0x6044, 0), (0x6061, 0)]) == 0x71
    assert pdo_notes.selecting_byte(tpdo[0], [(0x6041, 0), (0x6046, 1)]) is None, "an object outside the bit table"


@pytest.mark.parametrize(("node_id", "direction", "number", "entries"), ROUND_TRIPS,
                         ids=[f"{NODES[n].split('-')[1]}-{d}{k}" for n, d, k, _ in ROUND_TRIPS])
def test_round_trip(drives: tuple[Session, Plant], loop: asyncio.AbstractEventLoop, node_id: int,
                    direction: Direction, number: int, entries: list[tuple[int, int]]) -> None:
    session, plant = drives
    offered = {(m.index, m.subindex) for m in pdo.mappable_objects(session, node_id, direction)}
    assert set(entries) <= offered, "the picker offers these objects"
    report = loop.run_until_complete(pdo.apply_pdo(session, node_id, direction, number, PdoWrite(entries=entries),
                                                   ctx=SERVICE))
    assert report.ok, report.message
    assert report.pdo is not None and report.pdo.valid
    assert [(e.index, e.subindex) for e in report.pdo.entries] == entries
    assert all(e.name != "not in the profile" for e in report.pdo.entries)
    store = plant.nodes[node_id].store
    mapping = (0x1600 if direction == "rpdo" else 0x1A00) + number - 1
    assert store.get(mapping, 0) == len(entries)
    assert [store.get(mapping, sub) >> 8 for sub in range(1, len(entries) + 1)] == [
        (index << 8) | sub for index, sub in entries]
    again = loop.run_until_complete(pdo.read_pdo(session, node_id, direction, number))
    assert again.entries == report.pdo.entries and again.length_bytes == report.pdo.length_bytes


def test_motec_refuses_tpdo_type_255_nowhere_but_says_so(drives: tuple[Session, Plant],
                                                         loop: asyncio.AbstractEventLoop) -> None:
    """8400 motec ch. 8.4: 255 is 'not permissible'; the profile keeps the printed range, the tab says so."""
    session, _ = drives
    config = loop.run_until_complete(pdo.read_pdo(session, 5, "tpdo", 1))
    assert config.transmission_type == 254 and config.transmission_note is None
    assert any("C00324" in note for note in config.notes)
    rpdo2 = loop.run_until_complete(pdo.read_pdo(session, 5, "rpdo", 2))
    assert any("0x281" in note for note in rpdo2.notes) and any("C00593/2" in note for note in rpdo2.notes)


def test_refused_entry_leaves_the_lenze_pdo_disabled(drives: tuple[Session, Plant],
                                                     loop: asyncio.AbstractEventLoop) -> None:
    session, plant = drives
    store = plant.nodes[12].store

    def refuse_word_3(index: int, sub: int, raw: object) -> None:
        if index == 0x1A01 and raw == 0x58E00310:
            raise Abort(0x06040042)

    store.add_write_check(refuse_word_3)
    report = loop.run_until_complete(pdo.apply_pdo(session, 12, "tpdo", 2, PdoWrite(
        entries=[(0x58E0, 1), (0x58E0, 3)], cob_id=0x280 + 12), ctx=SERVICE))
    assert not report.ok and not report.enabled
    assert report.steps[-1].abort_code == "0x06040042" and not report.steps[-1].ok
    assert store.get(0x1801, 1) & 0x80000000


def test_micromaster_p2041_follows_the_canopen_mapping(drives: tuple[Session, Plant],
                                                       loop: asyncio.AbstractEventLoop) -> None:
    """MICROMASTER ch. 5.7.2 trace: with RPDO5 = control word + target velocity and TPDO5 = status word + actual
    speed the drive reads P2041.02 = 0x2103; ch. 5.6: TPDO5 every SYNC (1) is the high byte of P2041.00, whose low
    byte (TPDO1) keeps its power-on 0 (P2041.00 and 0x1800 sub 2 default to 0)."""
    session, plant = drives
    writes: list[tuple[Direction, list[tuple[int, int]], int]] = [
        ("rpdo", [(0x6040, 0), (0x6042, 0)], 255), ("tpdo", [(0x6041, 0), (0x6044, 0)], 1)]
    for direction, entries, trans_type in writes:
        report = loop.run_until_complete(pdo.apply_pdo(session, 3, direction, 5, PdoWrite(
            entries=entries, transmission_type=trans_type), ctx=SERVICE))
        assert report.ok, report.message
    store = plant.nodes[3].store
    assert store.get(0x27F9, 2) == 0x2103
    assert store.get(0x27F9, 0) == 0x0100
    assert not store.get(0x27F9, 1) & 1 << 9, "RPDO5 asynchronous (255): P2041.01 bit 9 = 0"
    tpdo5 = loop.run_until_complete(pdo.read_pdo(session, 3, "tpdo", 5))
    assert "P2041.02 high byte = 0x21" in " ".join(tpdo5.notes)
    assert {s.ref: s.value for s in tpdo5.settings} == {"P2041": "256 (0x0100)", "P2041.2": "0x2103"}
