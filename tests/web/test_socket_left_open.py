"""A live socket whose client went away ends its handler, also when it had nothing new to send: the node table of
an EtherCAT session (no heartbeat ages change it) kept its handler looping for ever after the browser closed, one
task per visit of the Plant page, and `drivebench serve` then ignored SIGTERM ("Waiting for background tasks to
complete"), so `docker stop` had to kill it and the lifespan's restores never ran."""

from __future__ import annotations

import asyncio
import signal
import subprocess
from pathlib import Path

import httpx
import pytest
import websockets

from tests.test_cli import free_port, poll
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = pytest.mark.slow  # a server process

STOP_WAIT_S = 60.0
"""Generous on a loaded machine; the server this test was written against never ended."""


async def _watch_once(url: str) -> None:
    async with websockets.connect(url) as socket:
        await asyncio.wait_for(socket.recv(), timeout=START_TIMEOUT_S)  # the table, once


def test_serve_ends_on_sigterm_after_a_browser_left_the_node_tables(tmp_path: Path) -> None:
    port = free_port()
    server = CliProcess("serve", "--port", str(port), "--demo",
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}"})
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as api:
            poll(lambda: api.get("/api/health").status_code == 200, START_TIMEOUT_S, "health")
            sessions = [session["id"] for session in api.get("/api/sessions").json()]
        assert "ethercat-line" in sessions
        for session_id in sessions:
            asyncio.run(_watch_once(f"ws://127.0.0.1:{port}/ws/sessions/{session_id}/nodes"))
        server.process.send_signal(signal.SIGTERM)
        try:
            code = server.process.wait(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"serve still runs {STOP_WAIT_S:.0f} s after SIGTERM:\n" + "".join(server.output[-5:]))
        assert code in (0, -signal.SIGTERM)
    finally:
        server.stop()
