"""What a profile tells the user speaks of manuals by name (issue 28 item 9): no "seed" manuals or texts, no
notes about what the simulator implements; every string the profile API serves is checked."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

from fastapi.testclient import TestClient

INTERNAL = re.compile(r"\bseeds?\b|\bsimulator\b", re.IGNORECASE)


def _strings(value: Any) -> Iterator[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for item in value.values():
            yield from _strings(item)
    elif isinstance(value, list):
        for item in value:
            yield from _strings(item)


def test_profile_texts_name_manuals_not_seeds_or_the_simulator(demo_api: TestClient) -> None:
    profiles = demo_api.get("/api/profiles").json()
    assert len(profiles) >= 6
    found = [(summary["id"], text) for summary in profiles
             for text in _strings(demo_api.get(f"/api/profiles/{summary['id']}").json()) if INTERNAL.search(text)]
    assert found == [], f"{len(found)} texts, first: {found[:3]}"
