"""What a server start imports that its first answers do not need (issue 33: /api/health within 2 s of a restart):
a fresh interpreter importing what ``drivebench serve`` imports leaves such libraries out until they are used."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BACKEND = Path(__file__).resolve().parents[1] / "backend"
NOT_AT_START = ("babel.messages", "cryptography")
"""Babel's catalogue code (only for a catalogue whose compiled ``.mo`` is missing or old, and the page scripts'
texts at the first page); cryptography's X.509 (``drivebench tls`` makes certificates, uvicorn's ssl serves them)."""


def test_importing_the_server_leaves_out_what_the_start_does_not_use() -> None:
    script = ("import json, sys; import drivebench.cli, drivebench.web.app; "
              "print(json.dumps(sorted(sys.modules)))")
    environment = {**os.environ, "PYTHONPATH": str(BACKEND)}
    done = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                          check=True, timeout=600)
    imported = json.loads(done.stdout.strip().splitlines()[-1])
    assert "drivebench.web.app" in imported
    assert [name for name in imported if name.startswith(NOT_AT_START)] == []
