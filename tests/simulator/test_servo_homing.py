"""Every CiA 402 homing method on the simulated servo's machine, stepped in simulated time: the limit switches at
±20 revolutions, the home switch a cam over the first half revolution above the mechanical zero, one index pulse
per revolution 100 increments past each whole one (4096 increments per revolution, 1 position unit = 1 °).

The expected home positions are worked out here from CiA 402-2's method descriptions, not from the model's plan:
index methods end at the first index pulse past their edge on their home side, the others at the edge itself."""

from __future__ import annotations

import pytest

from drivebench.device.drive import cia402
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.simulator.node import SimulatedNode
from drivebench.simulator.servo402 import CYCLE_S, Servo402

REV = 4096
LIMIT = 20 * REV
BELOW_CAM_INDEX, IN_CAM_INDEX, ABOVE_CAM_INDEX = -REV + 100, 100, REV + 100
LOW, HIGH = 0, REV // 2
ERROR = None  # homing error (status word bit 13)

FROM_ABOVE_THE_CAM = {  # started at 5.3 revolutions, above the home switch
    1: -LIMIT + 100 + 0 * REV, 2: LIMIT - REV + 100,
    3: ERROR, 4: ERROR,  # positive home switch: inactive, so they start positive, away from it, onto the limit
    5: ABOVE_CAM_INDEX, 6: IN_CAM_INDEX,
    7: BELOW_CAM_INDEX, 8: IN_CAM_INDEX, 9: IN_CAM_INDEX, 10: ABOVE_CAM_INDEX,  # turn round at the positive limit
    11: ABOVE_CAM_INDEX, 12: IN_CAM_INDEX, 13: IN_CAM_INDEX, 14: BELOW_CAM_INDEX,
    17: -LIMIT, 18: LIMIT, 19: ERROR, 20: ERROR, 21: HIGH, 22: HIGH,
    23: LOW, 24: LOW, 25: HIGH, 26: HIGH, 27: HIGH, 28: HIGH, 29: LOW, 30: LOW,
    33: 5 * REV + 100, 34: 6 * REV + 100, 35: 5.3 * REV, 37: 5.3 * REV,
}
FROM_BELOW_THE_CAM = {3: BELOW_CAM_INDEX, 4: IN_CAM_INDEX, 19: LOW, 20: LOW, 5: ERROR, 21: ERROR,
                      7: BELOW_CAM_INDEX, 11: ABOVE_CAM_INDEX}  # started at -3.7 revolutions


class Axis:
    def __init__(self, registry: ProfileRegistry, start_revs: float) -> None:
        node = SimulatedNode(registry.get("generic-cia402-servo"), 7, lambda cob_id, data: None)
        assert isinstance(node.drive, Servo402)
        self.drive = node.drive
        self.now = 0.0
        self.drive.mech = self.drive.demand = start_revs * REV
        for word in (0x06, 0x07, 0x0F):
            self.drive.store.set(0x6040, 0, word)
            self.step()

    def step(self, seconds: float = CYCLE_S) -> None:
        end = self.now + seconds
        while self.now < end:
            self.now += CYCLE_S
            self.drive.tick(self.now)

    def home(self, method: int) -> int:
        self.drive.store.set(0x6060, 0, 6)
        self.drive.store.set(0x6098, 0, method)
        self.drive.store.set(0x6040, 0, 0x1F)  # bit 4: homing operation start
        for _ in range(int(30 / CYCLE_S)):  # at most 30 s of simulated time
            self.step()
            word = self.drive.status_word()
            if word & 0x2000 or (word & 0x1400 == 0x1400):
                return word
        raise AssertionError(f"method {method} neither attained nor failed; at {self.drive.mech / REV:.2f} rev")


def test_every_listed_method_has_an_expectation() -> None:
    assert set(FROM_ABOVE_THE_CAM) == set(cia402.HOMING_METHODS)


@pytest.mark.parametrize(("start", "expected"), [(5.3, FROM_ABOVE_THE_CAM), (-3.7, FROM_BELOW_THE_CAM)],
                         ids=["above", "below"])
def test_homing_methods_find_their_edge_and_index_pulse(registry: ProfileRegistry, start: float,
                                                        expected: dict[int, float | None]) -> None:
    found: dict[int, float | None] = {}
    for method in expected:
        axis = Axis(registry, start)
        word = axis.home(method)
        found[method] = None if word & 0x2000 else round(axis.drive.home)
        if found[method] is not None:
            assert abs(axis.drive.position()) <= 5, f"method {method} stopped far past its home position"
        else:
            assert abs(axis.drive.demand) == LIMIT, f"method {method} failed off the limit switches"
    assert found == {method: None if home is None else round(home) for method, home in expected.items()}


def test_an_unknown_method_is_a_homing_error_without_motion(registry: ProfileRegistry) -> None:
    axis = Axis(registry, 2.0)
    word = axis.home(16)  # reserved in CiA 402-2
    assert word & 0x2000 and axis.drive.mech == 2 * REV
