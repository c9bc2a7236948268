"""A parameter reference past what CANopen can address (issue 28 item 8: ``P0700[999]``, sub-index 999 of a
one-byte field) is a 404 problem with the gate's headers on the lean read and on the full path, for reading and
writing, and leaves no audit row: the request never reaches the bus. A real uvicorn server with the demo plant."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, serve_app
from tests.web.test_access import own_db  # noqa: F401  (the fixture)

MM = "/api/sessions/demo-plant/nodes/3"


@pytest.fixture
def http(own_db: str) -> Iterator[httpx.Client]:  # noqa: F811  (each test's own database: its own audit rows)
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app) as url, httpx.Client(base_url=url, timeout=30) as client:
        yield client


def _audit(http: httpx.Client) -> list[dict[str, object]]:
    answer = http.get("/api/audit")
    assert answer.status_code == 200, answer.text
    return list(answer.json())


@pytest.mark.parametrize("ref", ["P0700[999]", "P0700[256]", "P0700.999", "P0700/300", "0x2000.0x1FF"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_sub_index_past_255_is_a_404_problem_everywhere(http: httpx.Client, ref: str) -> None:
    before = _audit(http)
    answers = {
        "lean read": http.get(f"{MM}/parameters/{ref}"),
        "full read": http.get(f"{MM}/parameters/{ref}", params={"transfer": "auto"}),
        "write": confirmed(http, "PUT", f"{MM}/parameters/{ref}", json={"value": 1}),
    }
    for how, answer in answers.items():
        assert answer.status_code == 404, (how, answer.status_code, answer.text)
        assert answer.headers["content-type"] == "application/problem+json", how
        assert answer.headers["x-frame-options"] == "DENY" and "content-security-policy" in answer.headers, how
        assert "255" in answer.json()["detail"], (how, answer.json())
    assert _audit(http) == before  # nothing was tried on the bus


def test_the_highest_sub_index_is_still_a_reference(http: httpx.Client) -> None:
    answer = http.get(f"{MM}/parameters/P0700[255]")
    assert answer.status_code == 404 and answer.json()["abort_code"] == "0x06090011", answer.text  # the device's no
