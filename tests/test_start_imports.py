"""What a server start imports that its first answers do not need (issue 33: /api/health within 2 s of a restart):
a fresh interpreter importing what ``drivebench serve`` imports leaves such libraries out until they are used."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

BACKEND = Path(__file__).resolve().parents[1] / "backend"
NOT_AT_START = ("babel.messages", "cryptography", "argon2")
"""Babel's catalogue code (only for a catalogue whose compiled ``.mo`` is missing or old, and the page scripts'
texts at the first page); cryptography's X.509 (``drivebench tls`` makes certificates, uvicorn's ssl serves them);
argon2's C bindings (the first sign-in or password set)."""


def _fresh_interpreter(script: str) -> Any:
    """What ``script`` prints last (JSON), run in a fresh interpreter with this tree's backend on the path."""
    environment = {**os.environ, "PYTHONPATH": str(BACKEND)}
    done = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                          check=True, timeout=600)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_the_server_leaves_out_what_the_start_does_not_use() -> None:
    script = ("import json, sys; import drivebench.cli, drivebench.web.app; "
              "print(json.dumps(sorted(sys.modules)))")
    printed = _fresh_interpreter(script)
    imported = printed
    assert "drivebench.web.app" in imported
    assert [name for name in imported if name.startswith(NOT_AT_START)] == []


def test_a_started_app_has_built_no_route_before_it_is_used() -> None:
    """FastAPI's state of a route (its parameters' pydantic fields, the response field, the handler) is built at
    first use, not as its module is imported: the app made, its access policy worked out and FastAPI's copies for
    the inclusions built (what requests are served by), no route has it; asked for, a route has it as FastAPI builds
    it (``web/deferred_route.py``)."""
    script = ("import json; from fastapi.routing import APIRoute; from drivebench.web import access_policy; "
              "from drivebench.web.app import create_app; app = create_app(); access_policy.precompute(app); "
              "routes = [r for r in access_policy.routes_in_place(app.router.routes) if isinstance(r, APIRoute)]; "
              "access_policy.build_effective_routes(app); before = sum('dependant' in vars(r) for r in routes); "
              "asked = [r.dependant.call is r.endpoint and r.response_field is not None for r in routes "
              "if r.path == '/api/health']; "
              "print(json.dumps([len(routes), before, asked]))")
    printed = _fresh_interpreter(script)
    routes, built_before_use, asked = printed
    assert routes > 250
    assert built_before_use == 0
    assert asked == [True]


def test_the_bus_load_tables_are_made_by_the_first_frame_counted() -> None:
    """The byte tables of the bus-load count (``transport/busload.py``) are made by the first frame counted, not as
    the server's modules are imported; counted, every frame has the bits of the bit-by-bit reference."""
    script = ("import json; import drivebench.cli, drivebench.web.app; from drivebench.transport import busload\n"
              "made = bool(busload._STUFF_STEP)\n"
              "frames = [(0x181, bytes([n, 0xFF - n, 0x0F])) for n in range(256)] + [(0x7E5, b'')]\n"
              "same = all(busload.frame_bits(cob, data) == busload.reference_bits(cob, False, False, len(data), data)"
              " for cob, data in frames)\n"
              "print(json.dumps([made, same, len(busload._STUFF_STEP)]))")
    printed = _fresh_interpreter(script)
    assert printed == [False, True, 2 * 5 * 256]
