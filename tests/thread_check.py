"""Threads left running by the tests: a test run ends with the threads it started (servers, buses, notifiers,
executors, simulator tickers) closed.

At the end of the run (each xdist worker: its own run) the threads still alive that were not there at the start
are reported after a grace period; with ``DRIVEBENCH_THREAD_CHECK=fail`` they fail the run (an error at the
teardown of the last test). ``DRIVEBENCH_THREAD_CHECK=module`` also prints, after each module, the
threads that module left alive: the way to find a leaking module (``-p no:randomly -s``, one worker).

Expected threads: the process-wide SDO worker pools of ``services/params/session_part.py`` (idle workers of a
``ThreadPoolExecutor`` that lives as long as the process)."""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator

import pytest

EXPECTED_PREFIXES = ("sdo_", "sdo-stop_")
"""Thread names of the process-wide pools (``ThreadPoolExecutor(thread_name_prefix="sdo")`` names them sdo_0 …)."""

GRACE_S = 15.0
"""How long threads get to end after the last fixture closed (a notifier's or server's join is not instant)."""

MODE = os.environ.get("DRIVEBENCH_THREAD_CHECK", "report")
"""``report`` (default), ``fail`` or ``module``. CI reports only until a whole run has been seen to end without
leaked threads; then .ci/run can set DRIVEBENCH_THREAD_CHECK=fail."""


def describe(thread: threading.Thread) -> str:
    target = getattr(thread, "_target", None)
    where = getattr(target, "__qualname__", None) or type(thread).__qualname__
    owner = getattr(target, "__self__", None)
    if owner is not None:
        where = f"{type(owner).__module__}.{where}"
    return f"{thread.name} ({where}{', daemon' if thread.daemon else ''})"


def left_over(before: set[threading.Thread], grace_s: float) -> list[threading.Thread]:
    """The threads alive that were not in ``before`` and are not the expected pools, after up to ``grace_s``."""
    deadline = time.monotonic() + grace_s
    while True:
        alive = [t for t in threading.enumerate()
                 if t not in before and t.is_alive() and not t.name.startswith(EXPECTED_PREFIXES)]
        if not alive or time.monotonic() >= deadline:
            return alive
        time.sleep(0.1)


def _say(config: pytest.Config, text: str) -> None:
    """Past pytest's output capture (a teardown's print would be swallowed)."""
    capture = config.pluginmanager.getplugin("capturemanager")
    with capture.global_and_fixture_disabled():
        sys.stderr.write(f"\n{text}\n")
        sys.stderr.flush()


def _summary(threads: list[threading.Thread]) -> str:
    counts: dict[str, int] = {}
    for thread in threads:
        key = describe(thread)
        counts[key] = counts.get(key, 0) + 1
    return "\n".join(f"  {n} x {what}" for what, n in sorted(counts.items(), key=lambda kv: -kv[1]))


@pytest.fixture(scope="session", autouse=True)
def no_leaked_threads(request: pytest.FixtureRequest) -> Iterator[None]:
    """Requested first, so closed last: after every other session fixture (servers, browser, PostgreSQL)."""
    before = set(threading.enumerate())
    yield
    leaked = left_over(before, GRACE_S)
    if not leaked:
        return
    text = f"{len(leaked)} threads still alive at the end of the run (started by the tests):\n{_summary(leaked)}"
    if MODE == "fail":
        pytest.fail(text, pytrace=False)
    _say(request.config, text)


@pytest.fixture(scope="module", autouse=True)
def module_threads(request: pytest.FixtureRequest) -> Iterator[None]:
    """With DRIVEBENCH_THREAD_CHECK=module: the threads each module leaves alive (session fixtures it started
    included: their names tell)."""
    if MODE != "module":
        yield
        return
    before = set(threading.enumerate())
    yield
    leaked = left_over(before, 2.0)
    if leaked:
        _say(request.config, f"[threads] {request.module.__name__}: {len(leaked)} left alive\n{_summary(leaked)}")
