"""A profile's message templates are checked on upload (issue 28 item 14), every one of them: named fields only,
the ones that field is given, no attribute or index access, no nested fields, width and precision at most 16.
``{value:>1000000000}`` in ``switches.node_parameter.invalid`` made a viewer's DIP request answer 1 GB; now the
upload is refused with the field and the reason, and nothing is stored. Through the real HTTP API."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from tests.web.test_tools_uploaded_device import PROFILE, upload

Change = Callable[[dict[str, Any]], None]


def _shipped(name: str) -> dict[str, Any]:
    profile = json.loads((settings.profiles_dir / f"{name}.json").read_text())
    profile["id"] = "acme-copy"
    profile.pop("switches", None)  # a second switch block under a shipped key is refused for its own reason
    return profile


def _set(path: str, text: str) -> Change:
    def change(profile: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        target = profile
        for key in parents:
            target = target[int(key)] if isinstance(target, list) else target[key]
        target[last] = text

    return change


WIDGET = "switches.node_parameter.invalid"
BAD = [
    (None, _set(WIDGET, "{value:>1000000000}"), "width"),
    (None, _set(WIDGET, "{value:.17f}"), "precision"),
    (None, _set(WIDGET, "{value:{lo}}"), "nested"),
    (None, _set(WIDGET, "{value.__class__}"), "{value.__class__}"),
    (None, _set(WIDGET, "{value[0]}"), "{value[0]}"),
    (None, _set(WIDGET, "{}"), "{}"),
    (None, _set(WIDGET, "{value!a}"), "!a"),
    (None, _set(WIDGET, "{value:x>99999}"), "width"),
    (None, _set(WIDGET, "{code:d}"), "{code:d}"),  # a text cannot be formatted as a number
    (None, _set(WIDGET, "{value"), "{value"),
    (None, _set("switches.baud_parameter.invalid", "{value:020000}"), "width"),
    (None, _set("switches.settings.0.meaning", "{node_id:,>40}"), "width"),
    ("lenze-8400-motec-canopen", _set("commands.save.done", "Node {node:>100000000} saved."), "width"),
    ("lenze-8400-motec-canopen", _set("commands.save.done", "Node {nod} saved."), "{nod}"),
    ("lenze-8400-motec-canopen", _set("control.jog.text", "{percent:.99g} %"), "precision"),
    ("siemens-micromaster4-canopen", _set("control.mode_refused", "{shown:>50000000}"), "width"),
    ("siemens-micromaster4-canopen", _set("control.modes_help", "Mode {mode.real}"), "{mode.real}"),
    ("siemens-micromaster4-canopen", _set("pdo_rules.mapping_bits.0.byte_text", "{bits:099999X}"), "width"),
]


@pytest.mark.parametrize(("base", "change", "words"), BAD)
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_template_past_the_rules_is_refused_with_where_and_why(api: TestClient, user_dir: Path, base: str | None,
                                                                 change: Change, words: str) -> None:
    profile = copy.deepcopy(PROFILE) if base is None else _shipped(base)
    change(profile)
    answer = upload(api, profile)
    assert answer.status_code == 422, answer.text[:300]
    assert answer.headers["content-type"].startswith("application/problem+json")
    detail = answer.json()["detail"]
    assert words in detail, detail
    assert len(answer.content) < 20_000
    assert profile["id"] not in [p["id"] for p in api.get("/api/profiles").json()]
    assert not user_dir.exists() or not list(user_dir.iterdir())


@pytest.mark.parametrize(("base", "change"), [
    (None, _set(WIDGET, "{code} = {value:>16} is outside {lo:03d} … {hi:g}.")),
    (None, _set(WIDGET, "{code!r} = {value:+.16f} {{not a field}}")),
    ("lenze-8400-motec-canopen", _set("control.jog.text", "{percent:g} % = {value:8.1f} {unit}")),
    ("siemens-micromaster4-canopen", _set("pdo_rules.mapping_bits.0.byte_text", "{ref} {byte} = 0x{bits:02X}")),
])
def test_the_formats_the_seed_profiles_use_still_load(api: TestClient, base: str | None, change: Change) -> None:
    profile = copy.deepcopy(PROFILE) if base is None else _shipped(base)
    change(profile)
    answer = upload(api, profile)
    assert answer.status_code in (200, 201), answer.text[:500]


def test_the_dip_calculator_answers_in_a_few_bytes(api: TestClient) -> None:
    profile = copy.deepcopy(PROFILE)
    profile["switches"]["node_parameter"]["invalid"] = "{code} = {value:>16} is outside {lo} … {hi}."
    assert upload(api, profile).status_code in (200, 201)
    answer = api.post("/api/tools/dip/acme-widget", json={"node_id": 62, "baud_kbit": 125})
    assert answer.status_code in (200, 422) and len(answer.content) < 20_000, answer.text[:300]
