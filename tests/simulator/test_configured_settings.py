"""A simulated device reports the node id and bit rate it runs with in its setting parameters (profile
``switches.settings``), as a commissioned device does: issue 28 item 11 (the MICROMASTER said P2010 = 10 kbit/s and
P2041.4 = 0 while it ran at 500 kbit/s)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import load_profile_file
from drivebench.device.profiles.profile import Profile
from drivebench.simulator.node import SimulatedNode

MM = 3
MM_PROFILE = REPO_ROOT / "device_profiles" / "siemens-micromaster4-canopen.json"


def _micromaster() -> Profile:
    return load_profile_file(MM_PROFILE.read_bytes(), MM_PROFILE.name)


def _raw(api: TestClient, ref: str) -> object:
    answer = api.get(f"/api/sessions/demo-plant/nodes/{MM}/parameters/{ref}")
    assert answer.status_code == 200, answer.text
    return answer.json()["raw"]


def test_the_demo_micromaster_reports_the_bus_it_runs_on(demo_api: TestClient) -> None:
    """The demo bus runs at 500 kbit/s: P2010 = 500 (kbit/s, §5.2) and the hundreds digit of P2041.4 = 5
    (§5.6 Table 5-1, with the factory reactions 0 0), P0918 = the node id."""
    assert _raw(demo_api, "P2010") == 500
    assert _raw(demo_api, "P2041.4") == 500
    assert _raw(demo_api, "P0918") == MM


@pytest.mark.parametrize(("node_id", "bitrate", "p2010", "p2041_4"),
                         [(4, 250_000, 250, 400), (9, 1_000_000, 1000, 700)])
def test_a_node_configured_for_another_bus_reports_it(node_id: int, bitrate: int, p2010: int, p2041_4: int) -> None:
    node = SimulatedNode(_micromaster(), node_id, lambda cob_id, data: None, bitrate=bitrate)
    assert node.store.get_ref("P2010") == p2010
    assert node.store.get_ref("P2041.4") == p2041_4
    assert node.store.get_ref("P0918") == node_id


def test_a_device_with_switches_keeps_its_setting_parameters() -> None:
    """The 8400 motec takes node id and bit rate from its DIP switches: C00350/C00351 keep their factory values."""
    path = REPO_ROOT / "device_profiles" / "lenze-8400-motec-canopen.json"
    profile = load_profile_file(path.read_bytes(), path.name)
    node = SimulatedNode(profile, 5, lambda cob_id, data: None, bitrate=1_000_000)
    plain = SimulatedNode(profile, 5, lambda cob_id, data: None)
    assert node.store.get_ref("C00350") == plain.store.get_ref("C00350")
    assert node.store.get_ref("C00351") == plain.store.get_ref("C00351")


def test_a_plant_value_wins_over_the_configured_one() -> None:
    node = SimulatedNode(_micromaster(), 3, lambda cob_id, data: None, bitrate=500_000,
                         values={"P2010": 125})
    assert node.store.get_ref("P2010") == 125
