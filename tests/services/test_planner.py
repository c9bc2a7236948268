"""Network planner: findings on planned networks, JSON round trip (the live comparison: test_tools_api)."""

from __future__ import annotations

import pytest

from drivebench.errors import InvalidValue
from drivebench.services.planning.planner import (
    CableInput,
    NetworkPlan,
    PlannedNode,
    PlanReport,
)
from drivebench.services.planning.planner import check_plan as check_with
from tests.conftest import shipped_switch_devices

MOTEC, EMF, MM4 = "lenze-8400-motec", "lenze-emf2178ib", "siemens-mm4"


def check_plan(plan: NetworkPlan) -> PlanReport:
    """The plan checked against the shipped profiles' ``switches`` sections."""
    return check_with(plan, shipped_switch_devices())


def kinds(plan: NetworkPlan) -> list[str]:
    return [f.kind for f in check_plan(plan).findings]


def test_clean_plan_has_no_errors() -> None:
    plan = NetworkPlan(
        nodes=[PlannedNode(device=MOTEC, node_id=n, baud_kbit=500) for n in (1, 2, 3)]
        + [PlannedNode(device=MM4, node_id=10, baud_kbit=500)]
    )
    report = check_plan(plan)
    assert report.ok, report.findings
    assert report.findings == []
    assert [r.cob_id for r in report.cob_table] == sorted(r.cob_id for r in report.cob_table)
    assert {r.hex for r in report.cob_table if r.node_id == 10} >= {"0x18A", "0x60A", "0x70A"}


def test_duplicate_node_id_reported_once() -> None:
    plan = NetworkPlan(
        nodes=[
            PlannedNode(name="conveyor", device=MOTEC, node_id=5, baud_kbit=250),
            PlannedNode(name="lift", device=EMF, node_id=5, baud_kbit=250),
        ]
    )
    report = check_plan(plan)
    assert kinds(plan) == ["duplicate_node_id"]
    assert "conveyor" in report.findings[0].message and not report.ok


def test_sdo2_collides_with_sdo1_of_node_plus_64() -> None:
    plan = NetworkPlan(
        nodes=[
            PlannedNode(device=EMF, node_id=3, baud_kbit=500, channels=["pdo1", "sdo2"]),
            PlannedNode(device=EMF, node_id=67, baud_kbit=500),
        ]
    )
    report = check_plan(plan)
    collisions = [f for f in report.findings if f.kind == "cob_id_collision"]
    assert {f.cob_id for f in collisions} == {0x643, 0x5C3}
    assert all(f.node_ids == [3, 67] for f in collisions)
    assert "address + 64" in collisions[0].message


def test_lenze_rpdo2_collides_with_tpdo2_of_next_node() -> None:
    plan = NetworkPlan(
        nodes=[
            PlannedNode(device=MOTEC, node_id=7, baud_kbit=500, pdo_ids="lenze"),
            PlannedNode(device=MOTEC, node_id=8, baud_kbit=500),
        ]
    )
    report = check_plan(plan)
    [collision] = [f for f in report.findings if f.kind == "cob_id_collision"]
    assert collision.cob_id == 0x288
    assert "0x281" in collision.message and "C00353 = 1" in collision.message
    plan.nodes[0].pdo_ids = "canopen"
    assert check_plan(plan).ok


def test_pdo_off_removes_collision() -> None:
    plan = NetworkPlan(
        nodes=[
            PlannedNode(device=MOTEC, node_id=7, baud_kbit=500, pdo_ids="lenze", channels=["pdo1"]),
            PlannedNode(device=MOTEC, node_id=8, baud_kbit=500),
        ]
    )
    assert check_plan(plan).ok


def test_mixed_baud_out_of_range_unsupported_and_unknown() -> None:
    plan = NetworkPlan(
        nodes=[
            PlannedNode(device=MOTEC, node_id=70, baud_kbit=500),
            PlannedNode(device=MOTEC, node_id=2, baud_kbit=10),
            PlannedNode(device=EMF, node_id=100, baud_kbit=500, channels=["pdo9"]),
            PlannedNode(device="acme", node_id=4, baud_kbit=500),
        ]
    )
    found = kinds(plan)
    assert found.count("out_of_range") == 1  # 8400 motec: 1 … 63; EMF2178IB 100 is fine by DIP
    assert {"unsupported_baud", "unknown_channel", "unknown_device", "mixed_baud"} <= set(found)
    assert "sdo2_reserved" not in found


def test_sdo2_above_63_warns() -> None:
    plan = NetworkPlan(nodes=[PlannedNode(device=EMF, node_id=70, baud_kbit=500, channels=["sdo2"])])
    [finding] = check_plan(plan).findings
    assert (finding.kind, finding.severity) == ("sdo2_reserved", "warning")


def test_cable_finding_uses_manual_tables() -> None:
    nodes = [PlannedNode(device=MOTEC, node_id=n, baud_kbit=125) for n in range(1, 29)]
    report = check_plan(NetworkPlan(nodes=nodes, cable=CableInput(cross_section_mm2=0.5, length_m=450)))
    assert report.cable is not None and report.cable.repeaters == 1
    assert [f.kind for f in report.findings] == ["cable"] and report.ok
    too_long = check_plan(NetworkPlan(nodes=nodes, cable=CableInput(length_m=650)))
    assert not too_long.ok


def test_json_export_import_round_trip() -> None:
    plan = NetworkPlan(
        name="Line 2",
        nodes=[
            PlannedNode(device=MOTEC, node_id=1, baud_kbit=500, pdo_ids="lenze", channels=["pdo1", "sdo2"])
        ],
        cable=CableInput(length_m=80),
    )
    assert NetworkPlan.from_json(plan.to_json()) == plan
    with pytest.raises(InvalidValue):
        NetworkPlan.from_json('{"nodes": [{"device": "x", "node_id": 200, "baud_kbit": 500}]}')
