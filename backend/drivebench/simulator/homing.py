"""CiA 402-2 homing methods as the simulated servo runs them: which switch edge a method seeks, from which side it
takes the index pulse, and the moves (phases) that find them on the simulated machine.

The machine (see ``servo402``): a negative and a positive limit switch at ``±limit``, and a home switch that is a
cam, active from ``cam[0]`` up to ``cam[1]``. Its lower edge acts as a *positive home switch* (active above the
edge: methods 3, 4, 19, 20), its upper edge as a *negative home switch* (active below: 5, 6, 21, 22); methods
7 to 14 and 23 to 30 use the cam's lower or upper edge and turn round at the limit switch their first move runs
onto. Methods 3 to 6 and 19 to 22 start towards the side the switch type lies on; started on the wrong side of the
cam they run onto a limit switch, and CiA 402 gives them no reversal there: homing error (status word bit 13).

Every method ends with a slow crossing of its edge in the direction of its home side (the last event is found at
the zero-search speed 0x6099.2, whatever the start), then with the index methods the next index pulse that way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    edge: str | None
    """"neg_limit", "pos_limit", "cam_low", "cam_high"; None: the index pulse alone (33, 34)."""
    side: int
    """The direction of the last edge crossing and of the index search (the home position lies that way)."""
    first: int
    """The first move while the method's switch is inactive."""
    index: bool = True
    reverses: bool = False
    """Turns round at a limit switch (7 ... 14, 23 ... 30)."""


def _methods() -> dict[int, Method]:
    table = {
        1: Method("neg_limit", 1, -1), 2: Method("pos_limit", -1, 1),
        3: Method("cam_low", -1, 1), 4: Method("cam_low", 1, 1),
        5: Method("cam_high", 1, -1), 6: Method("cam_high", -1, -1),
        7: Method("cam_low", -1, 1, reverses=True), 8: Method("cam_low", 1, 1, reverses=True),
        9: Method("cam_high", -1, 1, reverses=True), 10: Method("cam_high", 1, 1, reverses=True),
        11: Method("cam_high", 1, -1, reverses=True), 12: Method("cam_high", -1, -1, reverses=True),
        13: Method("cam_low", 1, -1, reverses=True), 14: Method("cam_low", -1, -1, reverses=True),
        33: Method(None, -1, -1), 34: Method(None, 1, 1),
    }
    without_index = {17: 1, 18: 2, **{method: method - 16 for method in range(19, 31)}}  # the edge is home
    for method, like in without_index.items():
        base = table[like]
        table[method] = Method(base.edge, base.side, base.first, index=False, reverses=base.reverses)
    return table


METHODS = _methods()
"""Methods that move (35 and 37 take the current position and need no plan)."""


@dataclass(frozen=True)
class Machine:
    limit: float
    cam: tuple[float, float]

    def position(self, edge: str) -> float:
        return {"neg_limit": -self.limit, "pos_limit": self.limit, "cam_low": self.cam[0],
                "cam_high": self.cam[1]}[edge]

    def side(self, edge: str, at: float) -> int:
        """Which side of ``edge`` a position lies on, by the switch it reads (a switch changes at its edge)."""
        if edge == "neg_limit":
            return -1 if at <= -self.limit else 1
        if edge == "pos_limit":
            return 1 if at >= self.limit else -1
        if edge == "cam_low":
            return 1 if at >= self.cam[0] else -1
        return -1 if at < self.cam[1] else 1

    def switch_active(self, edge: str, at: float) -> bool:
        if edge == "neg_limit":
            return at <= -self.limit
        if edge == "pos_limit":
            return at >= self.limit
        return self.cam[0] <= at < self.cam[1]


@dataclass(frozen=True)
class Phase:
    direction: int
    speed: float
    edge: str | None
    """The switch edge whose crossing in ``direction`` ends the phase; None: the next index pulse."""


def plan(method: int, at: float, machine: Machine, fast: float, slow: float, *,
         reversed_at_limit: bool = False) -> list[Phase]:
    """The phases of ``method`` from position ``at`` (``reversed_at_limit``: the first move ran onto a limit switch
    and the method turns round there)."""
    spec = METHODS[method]
    if spec.edge is None:
        return [Phase(spec.side, slow, None)]
    edge, side = spec.edge, spec.side
    towards = side if machine.side(edge, at) == -side else -side  # the first crossing of the edge
    first = towards if reversed_at_limit or machine.switch_active(edge, at) else spec.first
    if first != towards:
        return [Phase(first, fast, edge)]  # leads away from the edge: it runs onto a limit switch
    if towards == side:
        phases = [Phase(side, fast, edge), Phase(-side, slow, edge), Phase(side, slow, edge)]
    else:
        phases = [Phase(-side, fast, edge), Phase(side, slow, edge)]
    return phases + ([Phase(side, slow, None)] if spec.index else [])


def crossed(machine: Machine, phase: Phase, before: float, after: float) -> bool:
    """The phase's edge was crossed in its direction between two positions."""
    assert phase.edge is not None
    return machine.side(phase.edge, before) != machine.side(phase.edge, after) == phase.direction


def index_pulse(before: float, after: float, per_rev: float, offset: float) -> float | None:
    """The first index pulse (one per revolution, at ``offset`` past each whole one) passed from ``before`` to
    ``after``, in the direction of travel; None if none was."""
    if after == before:
        return None
    if after > before:
        pulse = (math.floor((before - offset) / per_rev) + 1) * per_rev + offset
        return pulse if pulse <= after else None
    pulse = (math.ceil((before - offset) / per_rev) - 1) * per_rev + offset
    return pulse if pulse >= after else None
