"""Fuzz every operation of the REST API from its OpenAPI spec (schemathesis) against the real app and demo plant.

No answer may be a server error: a 500 (or an exception out of the app) is a bug. 502/503/504 are what the design
gives a drive's SDO abort, a silent node or a missing adapter; they pass only as problem+json that names such a
fault (``sdo-abort-error``, ``sdo-timeout-error``, ``node-offline``, ``adapter-unavailable``, ``transport-error``).

Each operation gets schema-valid and schema-invalid cases, half with random path parameters and half aimed at
things that exist (session ``demo-plant``, nodes 3, 5 and 12 with their profiles and one object each), so the
handlers behind the 404s are reached too. Nothing is excluded: the operations that take the demo plant apart or
slow every later request (``LAST``: SDO settings, simulated faults, delete a node, close the session) run last, so
every other operation still meets a working plant. CI runs a few
derandomized examples per operation; ``benchmarks/fuzz_api.py`` runs many more with the same harness.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import sys
import threading
import traceback
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import requests
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode

from drivebench.config import REPO_ROOT
from drivebench.config import settings as app_settings
from drivebench.web.app import create_app
from tests.conftest import fresh_channel, serve_app

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

DEMO_PLANT = REPO_ROOT / "plants" / "demo.json"
DEVICE_FAULTS = {"/problems/sdo-abort-error", "/problems/sdo-timeout-error", "/problems/node-offline",
                 "/problems/adapter-unavailable", "/problems/transport-error",
                 "/problems/mapping-unanswered", "/problems/mapping-not-applied",  # an EtherCAT slave's PDO mapping
                 "/problems/lss-error", "/problems/lss-no-answer", "/problems/lss-step-failed"}  # LSS (no slave ...)
# What exists in the demo plant, one set of path parameters per node (an operation takes the names it has).
KNOWN = [
    {"session_id": "demo-plant", "node_id": 3, "profile_id": "siemens-micromaster4-canopen", "ref": "P0700"},
    {"session_id": "demo-plant", "node_id": 5, "profile_id": "lenze-8400-motec-canopen", "ref": "C00088"},
    {"session_id": "demo-plant", "node_id": 12, "profile_id": "lenze-8200-vector-emf2178ib", "ref": "0x1017.0"},
]
# Run last, in this order, each for its reason: what it changes would make every operation after it slow or moot.
LAST = {
    "POST /api/users":
        "may create the first admin: from then on every request without a sign-in is refused with 401, so the "
        "operations after it would only test the sign-in wall",
    "PUT /api/sessions/{session_id}/sdo-settings":
        "sets the session's SDO timeout and retries (up to 30 s x 10): every later request to a stopped node would "
        "wait that long",
    "PUT /api/sessions/{session_id}/simulator/nodes/{node_id}/faults":
        "switches on simulated SDO faults (up to 60 s latency, silence, aborts) for the nodes after it",
    "DELETE /api/sessions/{session_id}/nodes/{node_id}": "removes the demo plant's nodes",
    "DELETE /api/sessions/{session_id}": "closes the demo plant's session",
}
CI_EXAMPLES = 3
CALL_TIMEOUT_S = 30


@dataclasses.dataclass
class FuzzReport:
    """What a fuzz run saw: cases sent, answers by status, and the failures with a curl line to repeat them."""

    cases: int = 0
    statuses: collections.Counter[int | str] = dataclasses.field(default_factory=collections.Counter)
    failures: list[str] = dataclasses.field(default_factory=list)
    device_faults: int = 0

    def server_errors(self) -> int:
        return sum(n for status, n in self.statuses.items() if not isinstance(status, int) or status >= 500)


def operation_labels() -> list[str]:
    """Every operation of the spec as 'METHOD /path', those in LAST at the end (the spec needs no plant)."""
    spec = create_app().openapi()
    labels = [f"{method.upper()} {path}" for path, methods in spec["paths"].items() for method in methods]
    return [label for label in labels if label not in LAST] + [label for label in LAST if label in labels]


def send(case: Any, target: Target, report: FuzzReport) -> None:
    report.cases += 1
    try:
        response = case.call(base_url=target.base_url, session=target.session, timeout=CALL_TIMEOUT_S)
    except requests.RequestException as exc:  # no answer at all (the server dropped the connection or hung)
        report.statuses["no answer"] += 1
        report.failures.append(f"no answer: {exc!r}\n    {case.as_curl_command(base_url=target.base_url)}\n"
                               f"    the server's busy threads:\n{busy_threads()}")
        return
    report.statuses[response.status_code] += 1
    if response.status_code < 500:
        return
    body: dict[str, Any] = {}
    if (response.headers.get("content-type") or [""])[0].startswith("application/problem+json"):
        body = response.json()
    if response.status_code in (502, 503, 504) and body.get("type") in DEVICE_FAULTS:
        report.device_faults += 1
        return
    report.failures.append(f"{response.status_code} {response.text[:300]}\n"
                           f"    {case.as_curl_command(base_url=target.base_url)}")


def busy_threads() -> str:
    """Where the server's worker threads are (the server runs in this process): why a request hangs."""
    names = {thread.ident: thread.name for thread in threading.enumerate()}
    lines = []
    for ident, frame in sys._current_frames().items():
        stack = [f for f in traceback.extract_stack(frame) if "/drivebench/" in f.filename]
        if stack and names.get(ident, "").startswith("bus-work"):
            lines.append(f"      {names[ident]}: " + " <- ".join(f"{Path(f.filename).name}:{f.lineno} {f.name}"
                                                             for f in reversed(stack[-4:])))
    return "\n".join(lines) or "      (none in drivebench code)"


def can_be_invalid(operation: Any) -> bool:
    """Whether schema-invalid cases exist: a body, a query or header parameter, or a path parameter that is more
    than a free string (any string is a valid path segment)."""
    if list(operation.body) or list(operation.query) or list(operation.headers):
        return True
    return any(parameter.definition.get("schema", {}).get("type") != "string" or "pattern" in parameter.definition
               for parameter in operation.path_parameters)


def fuzz_operation(operation: Any, target: Target, max_examples: int, report: FuzzReport) -> None:
    """Schema-valid then schema-invalid cases for one operation, random and aimed at the demo plant."""
    names = {parameter.name for parameter in operation.path_parameters}
    aimed = [{k: v for k, v in known.items() if k in names} for known in KNOWN] if names else []
    modes = [GenerationMode.POSITIVE] + ([GenerationMode.NEGATIVE] if can_be_invalid(operation) else [])
    for mode in modes:
        strategies = [operation.as_strategy(generation_mode=mode)]
        strategies += [operation.as_strategy(generation_mode=mode, path_parameters=pins) for pins in aimed]

        @given(case=st.one_of(strategies))
        @settings(max_examples=max_examples, derandomize=True, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        def run(case: Any) -> None:
            send(case, target, report)

        try:
            run()
        except Unsatisfiable:  # an enum or boolean alone can be wrong only in ways a URL cannot carry
            assert mode is GenerationMode.NEGATIVE, f"no valid case could be made for {operation.label}"


@dataclasses.dataclass
class Target:
    """The API under fuzz: its spec as schemathesis reads it, where it runs, one keep-alive HTTP session."""

    schema: Any
    base_url: str
    session: requests.Session


@contextlib.contextmanager
def running_api(work: Path) -> Iterator[Target]:
    """The real app with the demo plant in uvicorn (one lifespan for the whole run), own database and uploads."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(app_settings, "database_url", f"sqlite:///{work / 'fuzz.db'}")
        patch.setattr(app_settings, "user_profiles_dir", work / "profiles")
        app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
        with serve_app(app) as base_url, requests.Session() as session:
            schema = schemathesis.openapi.from_dict(session.get(f"{base_url}/openapi.json", timeout=30).json())
            schema.config.output.sanitization.enabled = False  # the curl lines show the ids that were sent
            yield Target(schema, base_url, session)


@pytest.fixture(scope="module")
def target(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Target]:
    with running_api(tmp_path_factory.mktemp("fuzz")) as running:
        yield running


@pytest.mark.parametrize("label", operation_labels())
def test_no_server_error(target: Target, label: str) -> None:
    method, path = label.split(" ", 1)
    report = FuzzReport()
    fuzz_operation(target.schema[path][method], target, CI_EXAMPLES, report)
    assert report.cases > 0
    assert not report.failures, f"{label}: {len(report.failures)} server errors\n" + "\n".join(report.failures[:5])


def test_every_operation_of_the_spec_is_fuzzed() -> None:
    """Nothing left out: the parametrized list is the spec's whole list of operations."""
    spec = create_app().openapi()
    assert len(operation_labels()) == sum(len(methods) for methods in spec["paths"].values()) > 100


def test_the_operations_run_last_are_in_the_spec() -> None:
    labels = operation_labels()
    assert labels[-len(LAST):] == list(LAST)


# --- what the fuzz found, pinned -------------------------------------------------------------------------------
HUGE = 10**20  # past SQLite's 64-bit INTEGER: binding it raised OverflowError (a 500)


@pytest.mark.parametrize("method, url", [
    ("GET", f"/api/parameter-sets/{HUGE}"), ("GET", f"/api/parameter-sets/1?version={HUGE}"),
    ("DELETE", f"/api/parameter-sets/{HUGE}"), ("GET", f"/api/parameter-sets/{HUGE}/history"),
    ("GET", f"/api/parameter-downloads/{HUGE}"), ("POST", f"/api/parameter-downloads/{HUGE}/retry"),
    ("GET", f"/api/planned-networks/{HUGE}"), ("DELETE", f"/api/planned-networks/{HUGE}"),
    ("GET", f"/api/audit?node_id={HUGE}"), ("DELETE", f"/api/tokens/{HUGE}"), ("DELETE", f"/api/auth/tokens/{HUGE}"),
])
def test_an_id_no_row_can_have_is_refused_in_words(method: str, url: str, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(app_settings, "database_url", f"sqlite:///{tmp_path / 'db.sqlite'}")
    with TestClient(create_app(), raise_server_exceptions=False) as client:
        response = client.request(method, url)
    assert response.status_code == 422
    assert "less than or equal to" in response.json()["detail"]
