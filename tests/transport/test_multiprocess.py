"""Separate processes share one bus: `drivebench hub` and `drivebench simulate` run as their own processes, and a
session in the test process reads SDOs from the simulated drives and sees their heartbeats through the hub."""

from __future__ import annotations

import asyncio
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any

import httpx
import pytest

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.session_manager import SessionManager
from tests.conftest import screenshot

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

START_TIMEOUT_S = 60.0  # a cold interpreter importing the package on a loaded 2-core machine
DEMO_NODES = {3: "siemens-micromaster4-canopen", 5: "lenze-8400-motec-canopen", 7: "generic-cia402-servo",
              12: "lenze-8200-vector-emf2178ib"}


class CliProcess:
    """`drivebench ARGS` in a subprocess, its output read line by line in a thread."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.args = args
        self.process = subprocess.Popen(
            [sys.executable, "-m", "drivebench.cli", *args], cwd=REPO_ROOT, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
        self.output: list[str] = []
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._lines.put(line)
        self._lines.put(None)

    def wait_for_line(self, pattern: str, timeout_s: float = START_TIMEOUT_S) -> re.Match[str]:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self._lines.get(timeout=left)
            except queue.Empty:
                break
            if line is None:
                raise AssertionError(f"drivebench {' '.join(self.args)} ended ({self.process.wait()}):\n"
                                     + "".join(self.output))
            self.output.append(line)
            match = re.search(pattern, line)
            if match:
                return match
        raise AssertionError(f"drivebench {' '.join(self.args)} printed no /{pattern}/ in {timeout_s} s:\n"
                             + "".join(self.output))

    def stop(self) -> int:
        """SIGTERM, as a supervisor or `docker stop` sends it; a process that ignores it is killed."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            return self.process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=5)
            raise AssertionError(f"drivebench {' '.join(self.args)} ignored SIGTERM") from None


def start_hub() -> tuple[CliProcess, int]:
    hub = CliProcess("hub", "--port", "0")
    port = int(hub.wait_for_line(r"socketcand hub on 127\.0\.0\.1:(\d+)")[1])
    return hub, port


def start_simulator(bus: str) -> CliProcess:
    simulator = CliProcess("simulate", "--bus", bus, "--latency", "0ms")
    simulator.wait_for_line(r"Simulating 4 nodes")
    return simulator


@pytest.fixture
def hub_and_simulator() -> Iterator[str]:
    """A hub process and a simulator process on it; yields the bus spec to open."""
    hub, port = start_hub()
    simulator: CliProcess | None = None
    try:
        bus = f"socketcand:127.0.0.1:{port}/can0"
        simulator = start_simulator(bus)
        yield bus
    finally:
        codes = [simulator.stop() if simulator else 0, hub.stop()]
    assert codes == [0, 0], "both processes end cleanly on SIGTERM"


def run_outside_playwright(main: Callable[[], Coroutine[Any, Any, None]]) -> None:
    """``asyncio.run(main())`` in a thread of its own: a browser test earlier in the session leaves Playwright's
    event loop running in the main thread, where ``asyncio.run`` refuses to start."""
    errors: list[BaseException] = []

    def work() -> None:
        try:
            asyncio.run(main())
        except BaseException as exc:
            errors.append(exc)

    worker = threading.Thread(target=work)
    worker.start()
    worker.join(timeout=120)
    assert not worker.is_alive(), "the session work did not end"
    if errors:
        raise errors[0]


async def until(check: object, timeout_s: float = 15.0) -> None:
    assert callable(check)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        await asyncio.sleep(0.05)
    raise AssertionError("condition not met in time")


def test_a_session_reads_sdo_and_sees_heartbeats_of_drives_in_another_process(
        registry: ProfileRegistry, hub_and_simulator: str) -> None:
    async def main() -> None:
        manager = SessionManager(registry, sdo_timeout_s=2.0)  # three processes share two cores
        session = await manager.open(hub_and_simulator)
        try:
            for node_id, profile_id in DEMO_NODES.items():
                session.add_node(node_id, profile_id)
            # 8400 motec manual 9.3: C00061 (index 0x5FFF - 61 = 0x5FC2) on node 5 reads 43 (0x2B).
            assert await session.client(5).aupload(0x5FC2, 0) == bytes.fromhex("2B000000")
            assert int.from_bytes(await session.client(12).aupload(0x1018, 1), "little") == 0x3B
            found = {node.node_id for node in await session.scan(1.0)}
            assert found == set(DEMO_NODES)

            def states() -> dict[int, tuple[str, bool]]:
                return {node_id: session.nmt_state(node_id) for node_id in DEMO_NODES}

            await until(lambda: set(states().values()) == {("Pre-operational", True)})
            await session.nmt(NmtCommand.START)
            await until(lambda: set(states().values()) == {("Operational", True)})
        finally:
            await manager.close_all()

    run_outside_playwright(main)



def test_the_plant_page_opens_a_gateway_session_and_scans_drives_of_another_process(
        live_server: str, page: Any, hub_and_simulator: str) -> None:
    """The Plant page's form on a socketcand gateway (the hub), drives simulated by another process."""
    from playwright.sync_api import expect

    timeout_ms = 20_000
    page.goto(live_server + "/")
    form = page.locator("#open-session")
    form.locator("select[name=interface]").select_option("socketcand")
    form.locator("input[name=channel]").fill(hub_and_simulator.removeprefix("socketcand:"))
    form.locator("input[name=name]").fill("Gateway line")
    try:
        form.get_by_role("button", name="Open session").click()
        card = page.locator("#session-gateway-line")
        expect(card).to_contain_text(f"{hub_and_simulator}@500000", timeout=timeout_ms)
        card.get_by_role("button", name="Scan bus").click()
        for node_id in DEMO_NODES:
            node_row = page.locator(f"#node-gateway-line-{node_id}")
            expect(node_row.locator("td").nth(0)).to_have_text(str(node_id), timeout=timeout_ms)
            expect(node_row.locator(".nmt")).to_have_text("Pre-operational", timeout=timeout_ms)
        screenshot(page, "plant-gateway-session")
    finally:  # the live server is shared by the test session: leave it as it was
        httpx.delete(f"{live_server}/api/sessions/gateway-line", timeout=10)
