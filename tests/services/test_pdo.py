"""PDO configuration against a simulated drive over a real virtual bus: read, apply in the CiA 301 order with
read-back, rejections before anything is sent, and a failed apply that leaves the PDO disabled."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest

from drivebench.device.profiles.profile import Profile
from drivebench.errors import InvalidValue
from drivebench.services.bus.sessions import Session
from drivebench.services.pdos import pdo
from drivebench.services.pdos.pdo import PdoWrite
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile, PlantNode
from tests.conftest import fresh_channel
from tests.write_contexts import SERVICE

NODE = 7


def _obj(index: int, sub: int, name: str, data_type: str, access: str = "rw", default: object = 0,
         **extra: object) -> dict[str, object]:
    return {"index": index, "subindex": sub, "name": name, "data_type": data_type, "access": access,
            "default": default, **extra}


def servo_profile() -> Profile:
    """A CiA 402-like drive: RPDO1/TPDO1 with 4 mapping entries, controlword/statusword/velocities mappable."""
    objects = [_obj(0x1000, 0, "Device type", "UNSIGNED32", "ro", 0x00020192),
               _obj(0x1017, 0, "Producer heartbeat time", "UNSIGNED16", default=0)]
    for comm, mapping, base in ((0x1400, 0x1600, "$NODEID+0x200"), (0x1800, 0x1A00, "$NODEID+0x180")):
        objects += [_obj(comm, 0, "Highest sub-index supported", "UNSIGNED8", "ro", 5, object_type="RECORD"),
                    _obj(comm, 1, "COB-ID", "UNSIGNED32", default_expr=base, default=None, object_type="RECORD"),
                    _obj(comm, 2, "Transmission type", "UNSIGNED8", default=255, object_type="RECORD",
                         selection={"0": "sync acyclic", "1": "every SYNC", "254": "event (mfr)",
                                    "255": "event (profile)"}),
                    _obj(comm, 3, "Inhibit time", "UNSIGNED16", object_type="RECORD"),
                    _obj(comm, 5, "Event timer", "UNSIGNED16", object_type="RECORD"),
                    _obj(mapping, 0, "Number of mapped objects", "UNSIGNED8", object_type="RECORD", max=4)]
        objects += [_obj(mapping, sub, f"Mapping entry {sub}", "UNSIGNED32", object_type="RECORD")
                    for sub in range(1, 5)]
    objects += [_obj(0x6040, 0, "Controlword", "UNSIGNED16", pdo_mappable=True),
                _obj(0x6041, 0, "Statusword", "UNSIGNED16", "ro", pdo_mappable=True),
                _obj(0x6042, 0, "vl target velocity", "INTEGER16", pdo_mappable=True, unit="rpm"),
                _obj(0x6044, 0, "vl velocity actual value", "INTEGER16", "ro", pdo_mappable=True, unit="rpm"),
                _obj(0x6064, 0, "Position actual value", "INTEGER32", "ro", pdo_mappable=True),
                _obj(0x6065, 0, "Following error window", "UNSIGNED32")]
    return Profile.model_validate({"id": "test-servo", "family": "test", "identity": {
        "vendor_name": "Test", "product_name": "Servo"}, "features": {"rpdo_count": 1, "tpdo_count": 1},
        "objects": objects})


class Profiles:
    def __init__(self, profile: Profile) -> None:
        self.profile = profile

    def get(self, profile_id: str) -> Profile:
        return self.profile

    def find_by_identity(self, vendor_id: int | None, product_code: int | None) -> Profile | None:
        return self.profile


@pytest.fixture
def loop() -> Iterator[asyncio.AbstractEventLoop]:
    event_loop = asyncio.new_event_loop()
    yield event_loop
    event_loop.close()


@pytest.fixture
def servo(loop: asyncio.AbstractEventLoop) -> Iterator[tuple[Session, Plant]]:
    profiles = Profiles(servo_profile())
    channel = fresh_channel()
    plant = Plant(PlantFile(name="pdo", bus=f"virtual:{channel}@500000",
                            nodes=[PlantNode(node_id=NODE, profile="test-servo", heartbeat_ms=0)]),
                  profiles.get).start()
    manager = SessionManager(profiles)
    session = loop.run_until_complete(manager.open(f"virtual:{channel}@500000", name="pdo"))
    session.add_node(NODE, "test-servo")
    yield session, plant
    loop.run_until_complete(manager.close_all())
    plant.stop()


def test_read_pdos_names_the_mapping(servo: tuple[Session, Plant], loop: asyncio.AbstractEventLoop) -> None:
    session, _ = servo
    configs = loop.run_until_complete(pdo.read_pdos(session, NODE))
    assert [(c.direction, c.number) for c in configs] == [("rpdo", 1), ("tpdo", 1)]
    rpdo1 = configs[0]
    assert rpdo1.cob_id == 0x200 + NODE and rpdo1.valid and rpdo1.entries == []
    assert rpdo1.transmission_type == 255 and rpdo1.transmission_text.startswith("event-driven")
    assert rpdo1.max_entries == 4
    mappable = {m.index for m in pdo.mappable_objects(session, NODE, "rpdo")}
    assert mappable == {0x6040, 0x6042}, "an RPDO may only map writable mappable objects"


def test_apply_writes_in_cia301_order_and_verifies(servo: tuple[Session, Plant],
                                                   loop: asyncio.AbstractEventLoop) -> None:
    session, plant = servo
    write = PdoWrite(entries=[(0x6041, 0), (0x6044, 0), (0x6064, 0)], transmission_type=1, event_timer_ms=100)
    report = loop.run_until_complete(pdo.apply_pdo(session, NODE, "tpdo", 1, write, ctx=SERVICE))
    assert report.ok, report.message
    assert [s.step.split(" ")[0] for s in report.steps] == [
        "disable", "disable", "entry", "entry", "entry", "enable", "transmission", "event", "enable"]
    assert report.steps[0].value == f"0x{0x80000000 | (0x180 + NODE):08X}"
    assert report.pdo is not None and report.pdo.valid and report.pdo.length_bytes == 8
    assert [e.name for e in report.pdo.entries] == ["Statusword", "vl velocity actual value",
                                                    "Position actual value"]
    store = plant.nodes[NODE].store
    assert store.get(0x1A00, 0) == 3 and store.get(0x1A00, 1) == 0x60410010
    assert store.get(0x1800, 2) == 1


def test_rejections_before_anything_is_sent(servo: tuple[Session, Plant], loop: asyncio.AbstractEventLoop) -> None:
    session, plant = servo
    store = plant.nodes[NODE].store
    before = {key: value for key, value in store.snapshot().items() if 0x1400 <= key[0] <= 0x1BFF}
    cases: list[tuple[pdo.Direction, PdoWrite, str]] = [
        ("tpdo", PdoWrite(entries=[(0x6064, 0), (0x6064, 0), (0x6041, 0)]), "at most 8"),
        ("rpdo", PdoWrite(entries=[(0x6065, 0)]), "cannot be mapped"),
        ("rpdo", PdoWrite(entries=[(0x6041, 0)]), "cannot be mapped"),  # read-only into an RPDO
        ("rpdo", PdoWrite(entries=[(0x6040, 0)] * 5), "at most 4 mapping entries"),
        ("rpdo", PdoWrite(entries=[(0x6040, 0)], transmission_type=200), "not permitted"),
    ]
    for direction, write, message in cases:
        with pytest.raises(InvalidValue, match=message):
            loop.run_until_complete(pdo.apply_pdo(session, NODE, direction, 1, write, ctx=SERVICE))
    after = {key: value for key, value in store.snapshot().items() if 0x1400 <= key[0] <= 0x1BFF}
    assert after == before, "nothing was written to the PDO objects"


def test_failed_apply_leaves_the_pdo_disabled(servo: tuple[Session, Plant], loop: asyncio.AbstractEventLoop) -> None:
    """The drive refuses the second entry mid-sequence (as a device with a stricter mapping table would)."""
    session, plant = servo
    store = plant.nodes[NODE].store

    def refuse_velocity(index: int, sub: int, raw: object) -> None:
        from drivebench.simulator.store import Abort

        if index == 0x1600 and raw == 0x60420010:
            raise Abort(0x06040041)

    store.add_write_check(refuse_velocity)
    report = loop.run_until_complete(pdo.apply_pdo(session, NODE, "rpdo", 1,
                                                   PdoWrite(entries=[(0x6040, 0), (0x6042, 0)]), ctx=SERVICE))
    assert not report.ok and not report.enabled
    failed = report.steps[-1]
    assert failed.abort_code == "0x06040041" and "mapped" in (failed.abort_text or "").lower()
    assert "left disabled" in report.message
    assert report.pdo is not None and not report.pdo.valid
    assert store.get(0x1400, 1) & 0x80000000


def test_cob_id_of_another_nodes_pdo_is_flagged(servo: tuple[Session, Plant], loop: asyncio.AbstractEventLoop) -> None:
    """Node 8 is known to the session (not simulated: only its predefined identifiers matter). The Lenze base ID
    case: an RPDO on 0x281 + 7 = 0x288 receives TPDO2 of node 8; a TPDO on 0x188 is a second producer of TPDO1.
    The servo's profile has no alternative base identifiers, so no base ID is named (test_cobids: the 8400 motec's)."""
    session, _ = servo
    session.add_node(8, "test-servo")
    assert loop.run_until_complete(pdo.read_pdo(session, NODE, "rpdo", 1)).conflicts == []
    rpdo = loop.run_until_complete(pdo.apply_pdo(session, NODE, "rpdo", 1, PdoWrite(cob_id=0x288, entries=[]),
                                                 ctx=SERVICE))
    assert rpdo.pdo is not None and rpdo.pdo.conflicts == [
        "COB-ID 0x288 is also TPDO2 of node 8: this RPDO receives what node 8 sends - wanted only for cross "
        "communication."]
    tpdo = loop.run_until_complete(pdo.apply_pdo(session, NODE, "tpdo", 1, PdoWrite(cob_id=0x188, entries=[]),
                                                 ctx=SERVICE))
    assert tpdo.pdo is not None and tpdo.pdo.conflicts == [
        "COB-ID 0x188 is also TPDO1 of node 8: two producers on one identifier."]
