"""Simulator test fixtures: an independent CANopen master on the module's plant bus."""

from __future__ import annotations

from collections.abc import Iterator

import canopen
import pytest

from drivebench.simulator.plant import Plant
from tests.simulator.canopen_master import connected


@pytest.fixture
def master(channel: str, plant: Plant) -> Iterator[canopen.Network]:
    """canopen's Network on the bus of the module's ``plant`` fixture (started first)."""
    with connected(channel) as network:
        yield network
