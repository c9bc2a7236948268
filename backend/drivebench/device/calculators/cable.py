"""Bus cable planning from the 8400 motec CANopen manual §5.2.4 (tables [5-1] and [5-2]).

Steps as the manual gives them: (1) total cable length for the baud rate, (2) segment cable length for the
node count and cross-section, (3) if the segment length is smaller than the required length, repeaters divide
the cable into segments; each repeater costs its "cable reduction" (Lenze repeater type 2176: 30 m).

The manual's worked example (125 kbit/s, 0.5 mm², 28 nodes, 450 m) subtracts the reduction from the segment
after the repeater: 360 m + (360 m - 30 m) = 690 m, which is more than the 600 m total for 125 kbit/s. The
EMF2178IB manual (§5, example 2) subtracts it from the total instead (630 m - 30 m). Both limits are physical
(segment: line resistance and load; total: signal delay), so the plan applies both and reports each figure.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, Field

from drivebench.errors import InvalidValue, OutOfRange
from drivebench.i18n import N_, _

TOTAL_LENGTH_M: dict[int, int] = {20: 4013, 50: 1575, 125: 600, 250: 275, 500: 113, 800: 38, 1000: 13}
"""Table [5-1]: baud rate [kbit/s] -> max. bus length [m]."""

CROSS_SECTIONS_MM2: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0)

SEGMENT_LENGTH_M: dict[int, tuple[int, int, int, int]] = {
    2: (240, 430, 650, 940),
    5: (230, 420, 640, 920),
    10: (230, 410, 620, 900),
    20: (210, 390, 580, 850),
    32: (200, 360, 550, 800),
    63: (170, 310, 470, 690),
}
"""Table [5-2]: max. nodes per segment -> segment length [m] for 0.25 / 0.5 / 0.75 / 1 mm²."""

REPEATER_2176_REDUCTION_M = 30

SELECTION_EXAMPLE = {
    "given": N_("0.5 mm², 63 nodes, Lenze repeater type 2176 (cable reduction 30 m)"),
    "baud_kbit": [20, 50, 125, 250, 500, 800, 1000],
    "max_cable_length_m": [4013, 1575, 600, 275, 113, 38, 13],
    "segment_cable_length_m": [270, 270, 270, 270, 113, 38, 13],
    "repeaters": [15, 6, 2, 1, 0, 0, 0],
    "note": N_(
        "As printed in §5.2.4. The segment length 270 m does not follow from table [5-2] (310 m for 63 nodes "
        "at 0.5 mm², 280 m after the 30 m reduction), and the repeater counts do not follow one rule "
        "(20/50 kbit/s: total / segment rounded up; 125/250 kbit/s: one fewer)."
    ),
}
"""Its ``given`` and ``note`` are N_() texts: translated where shown (:func:`selection_example`)."""


def selection_example() -> dict[str, object]:
    """The selection example with its words in the current language."""
    return {**SELECTION_EXAMPLE, "given": _(str(SELECTION_EXAMPLE["given"])), "note": _(str(SELECTION_EXAMPLE["note"]))}


class CablePlan(BaseModel):
    baud_kbit: int
    cross_section_mm2: float
    nodes: int
    required_length_m: float
    repeater_reduction_m: int
    total_length_m: int
    """Table [5-1] for the baud rate."""
    segment_row_nodes: int
    """The table [5-2] row used (smallest row with at least ``nodes``)."""
    segment_length_m: int
    repeaters: int
    """Repeaters needed (0: none)."""
    segment_capacity_m: float
    """Length the segments allow with that many repeaters: first segment + (segment - reduction) per repeater
    (the manual's worked example: 360 + 330 = 690 m)."""
    delay_limit_m: float
    """Total length for the baud rate minus the reduction of each repeater."""
    max_length_m: float
    """min(segment capacity, delay limit): what the plan allows."""
    feasible: bool
    steps: list[str] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)


def segment_length(nodes: int, cross_section_mm2: float) -> tuple[int, int]:
    """Table [5-2]: (row used, max. segment length [m])."""
    if cross_section_mm2 not in CROSS_SECTIONS_MM2:
        raise InvalidValue(_("Cross-section {section} mm² is not in table [5-2] ({sections} mm²).").format(
            section=cross_section_mm2, sections=", ".join(str(c) for c in CROSS_SECTIONS_MM2)))
    for row, lengths in SEGMENT_LENGTH_M.items():
        if nodes <= row:
            return row, lengths[CROSS_SECTIONS_MM2.index(cross_section_mm2)]
    raise OutOfRange(_("{nodes} nodes per segment: table [5-2] ends at 63.").format(nodes=nodes))


def total_length(baud_kbit: int) -> int:
    if baud_kbit not in TOTAL_LENGTH_M:
        raise InvalidValue(_("{baud} kbit/s is not in table [5-1] ({rates} kbit/s).").format(
            baud=baud_kbit, rates=", ".join(str(b) for b in TOTAL_LENGTH_M)))
    return TOTAL_LENGTH_M[baud_kbit]


def _limits(seg: int, total: int, reduction: int, repeaters: int) -> tuple[float, float]:
    """(segment capacity, delay limit) with ``repeaters`` repeaters."""
    return seg + repeaters * (seg - reduction), total - repeaters * reduction


def plan_cable(
    baud_kbit: int,
    cross_section_mm2: float,
    nodes: int,
    required_length_m: float,
    repeater_reduction_m: int = REPEATER_2176_REDUCTION_M,
) -> CablePlan:
    if nodes < 2:
        raise OutOfRange(_("A CAN segment has at least 2 nodes."))
    if required_length_m <= 0:
        raise OutOfRange(_("The required cable length must be greater than 0 m."))
    total = total_length(baud_kbit)
    row, seg = segment_length(nodes, cross_section_mm2)
    steps = [
        _("1. Total cable length at {baud} kbit/s: {total} m (table [5-1]).").format(baud=baud_kbit, total=total),
        _("2. Segment cable length for {nodes} nodes at {section} mm²: {segment} m (table [5-2], row {row} "
          "nodes).").format(nodes=nodes, section=cross_section_mm2, segment=seg, row=row),
    ]
    per_repeater = seg - repeater_reduction_m
    if seg >= required_length_m:
        steps.append(_("3. {segment} m ≥ {required} m: no repeater needed for the segment length.").format(
            segment=seg, required=f"{required_length_m:g}"))
        repeaters = 0
    else:
        steps.append(_("3. {segment} m < {required} m: a repeater is needed after {segment} m.").format(
            segment=seg, required=f"{required_length_m:g}"))
        repeaters = math.ceil((required_length_m - seg) / per_repeater) if per_repeater > 0 else 1
    capacity, delay_limit = _limits(seg, total, repeater_reduction_m, repeaters)
    feasible = (per_repeater > 0 or repeaters == 0) and required_length_m <= min(capacity, delay_limit)
    best_note = None
    if not feasible and per_repeater > 0:
        # More repeaters add segment length but cost total length: the longest cable is where the two limits
        # cross, at (total - segment) / segment repeaters. Report that plan, not a count that makes it worse.
        crossing = max(0.0, (total - seg) / seg)
        repeaters = max((math.floor(crossing), math.ceil(crossing)),
                        key=lambda count: (min(_limits(seg, total, repeater_reduction_m, count)), -count))
        capacity, delay_limit = _limits(seg, total, repeater_reduction_m, repeaters)
        best_note = _("The longest cable possible at {baud} kbit/s with {nodes} nodes at {section} mm² is {length} m, "
                      "with {repeaters} repeater(s).").format(baud=baud_kbit, nodes=nodes, section=cross_section_mm2,
                                                               length=f"{min(capacity, delay_limit):g}",
                                                               repeaters=repeaters)
    max_length = min(capacity, delay_limit)
    if repeaters:
        steps.append(_("4. With {repeaters} repeater(s): segments {segment} m + {repeaters} x ({segment} m - "
                       "{reduction} m) = {capacity} m.").format(repeaters=repeaters, segment=seg,
                                                               reduction=repeater_reduction_m,
                                                               capacity=f"{capacity:g}"))
    steps.append(_("{step}. Signal delay: {total} m - {repeaters} x {reduction} m = {limit} m for {baud} "
                   "kbit/s.").format(step=5 if repeaters else 4, total=total, repeaters=repeaters,
                                     reduction=repeater_reduction_m, limit=f"{delay_limit:g}", baud=baud_kbit))
    notes = []
    if capacity > delay_limit:
        notes.append(_("The segments would allow more than the baud rate's total length: the total length "
                       "({limit} m after repeater delays) is the limit.").format(limit=f"{delay_limit:g}"))
    if not feasible:
        notes.append(_("{required} m is not possible at {baud} kbit/s: lower the baud rate or the cable "
                       "length.").format(required=f"{required_length_m:g}", baud=baud_kbit))
    if best_note:
        notes.append(best_note)
    return CablePlan(
        baud_kbit=baud_kbit,
        cross_section_mm2=cross_section_mm2,
        nodes=nodes,
        required_length_m=required_length_m,
        repeater_reduction_m=repeater_reduction_m,
        total_length_m=total,
        segment_row_nodes=row,
        segment_length_m=seg,
        repeaters=repeaters,
        segment_capacity_m=capacity,
        delay_limit_m=delay_limit,
        max_length_m=max_length,
        feasible=feasible,
        steps=steps,
        notes=notes,
    )
