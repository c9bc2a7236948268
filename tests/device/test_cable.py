"""Cable planning: 8400 motec manual §5.2.4 tables [5-1], [5-2] and its worked example."""

from __future__ import annotations

import pytest

from drivebench.device.calculators.cable import SEGMENT_LENGTH_M, plan_cable, segment_length, total_length
from drivebench.errors import InvalidValue, OutOfRange


def test_manual_worked_example_125k_05mm2_28_nodes_450m() -> None:
    """§5.2.4: 600 m total, 360 m segment (32-node row), repeater after 360 m, 360 + (360 - 30) = 690 m."""
    plan = plan_cable(125, 0.5, 28, 450)
    assert plan.total_length_m == 600
    assert (plan.segment_row_nodes, plan.segment_length_m) == (32, 360)
    assert plan.repeaters == 1
    assert plan.segment_capacity_m == 690
    assert plan.feasible
    # The 690 m exceed the 600 m total for 125 kbit/s; the repeater delay (EMF2178IB manual: total - 30 m)
    # makes the real limit 570 m.
    assert (plan.delay_limit_m, plan.max_length_m) == (570, 570)


@pytest.mark.parametrize(
    ("kbit", "metres"), [(20, 4013), (50, 1575), (125, 600), (250, 275), (500, 113), (800, 38), (1000, 13)]
)
def test_table_5_1_rows(kbit: int, metres: int) -> None:
    assert total_length(kbit) == metres
    assert plan_cable(kbit, 1.0, 2, min(metres, 940)).feasible  # 940 m: 2 nodes at 1 mm², no repeater
    assert not plan_cable(kbit, 1.0, 2, metres + 1).feasible


@pytest.mark.parametrize(("nodes", "lengths"), list(SEGMENT_LENGTH_M.items()))
def test_table_5_2_rows(nodes: int, lengths: tuple[int, ...]) -> None:
    printed = {
        2: (240, 430, 650, 940),
        5: (230, 420, 640, 920),
        10: (230, 410, 620, 900),
        20: (210, 390, 580, 850),
        32: (200, 360, 550, 800),
        63: (170, 310, 470, 690),
    }
    assert lengths == printed[nodes]
    for cross_section, metres in zip((0.25, 0.5, 0.75, 1.0), lengths, strict=True):
        assert segment_length(nodes, cross_section) == (nodes, metres)


def test_no_repeater_when_segment_is_long_enough() -> None:
    plan = plan_cable(125, 0.5, 28, 300)
    assert (plan.repeaters, plan.feasible) == (0, True)


def test_several_repeaters_at_low_baud() -> None:
    plan = plan_cable(20, 0.25, 63, 1000)  # 170 m segments, 140 m after each repeater
    assert plan.repeaters == 6  # 170 + 5 * 140 = 870 < 1000 <= 170 + 6 * 140 = 1010
    assert (plan.segment_capacity_m, plan.delay_limit_m, plan.feasible) == (1010, 4013 - 6 * 30, True)


def test_invalid_inputs() -> None:
    with pytest.raises(InvalidValue):
        plan_cable(10, 0.5, 5, 100)
    with pytest.raises(InvalidValue):
        plan_cable(125, 0.34, 5, 100)
    with pytest.raises(OutOfRange):
        segment_length(64, 0.5)


def test_a_cable_longer_than_the_baud_rate_allows_reports_the_longest_possible_plan() -> None:
    """More repeaters add segment length but each costs 30 m of the total: past the crossing of the two limits
    a plan only gets shorter. 99,999 m at 20 kbit/s once gave 357 repeaters and a negative maximum."""
    plan = plan_cable(20, 0.5, 63, 99_999)  # 310 m segments, 280 m after each repeater, 4013 m total
    assert plan.feasible is False
    assert plan.repeaters == 12  # 11: min(310 + 11 * 280, 4013 - 11 * 30) = 3390; 12: min(3670, 3653) = 3653
    assert (plan.segment_capacity_m, plan.delay_limit_m, plan.max_length_m) == (3670, 3653, 3653)
    assert any("longest cable possible at 20 kbit/s" in note and "3653 m, with 12 repeater(s)" in note
               for note in plan.notes)
    for count in range(0, 40):  # no other repeater count does better
        assert min(310 + count * 280, 4013 - count * 30) <= plan.max_length_m


def test_just_beyond_the_worked_example_the_delay_limit_decides() -> None:
    """28 nodes at 0.5 mm² and 125 kbit/s: one repeater gives 690 m of segments but 600 - 30 = 570 m of total."""
    assert plan_cable(125, 0.5, 28, 570).feasible is True
    plan = plan_cable(125, 0.5, 28, 580)
    assert (plan.feasible, plan.repeaters, plan.max_length_m) == (False, 1, 570)


def test_a_huge_length_is_answered_at_once() -> None:
    plan = plan_cable(1000, 0.25, 2, 1e12)
    assert (plan.feasible, plan.repeaters, plan.max_length_m) == (False, 0, 13)
