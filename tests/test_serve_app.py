"""The tests' uvicorn helper (``tests.conftest.serve_app``) leaves no server behind, also when one is slow to start."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest
from fastapi import FastAPI

from tests.conftest import serve_app, wait_until


def _servers() -> list[threading.Thread]:
    return [thread for thread in threading.enumerate()
            if getattr(getattr(thread, "_target", None), "__qualname__", "") == "Server.run" and thread.is_alive()]


def test_a_server_that_did_not_start_in_time_is_stopped_once_it_has() -> None:
    """Start-up (here a lifespan of 2 s, under load the demo plant's took over a minute) outlasts the wait: the test
    fails in words and the server, once up, ends rather than running on with its threads for the rest of the run."""

    @asynccontextmanager
    async def slow_start(_: FastAPI) -> AsyncIterator[None]:
        await asyncio.sleep(2)
        yield

    before = set(_servers())
    with pytest.raises(AssertionError, match=r"did not start in 0\.2 s"), serve_app(FastAPI(lifespan=slow_start),
                                                                                   start_timeout_s=0.2):
        pass
    assert wait_until(lambda: not set(_servers()) - before, 20), "the slow server runs on"
