"""The request path stays lean: no route's dependency hops to the thread pool just to look something up."""

from __future__ import annotations

import gc
import inspect
from collections.abc import Iterator

import pytest
from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, iter_route_contexts
from fastapi.testclient import TestClient

from drivebench.web import heap
from drivebench.web.app import create_app


def _sync_dependencies(dependant: Dependant) -> Iterator[str]:
    for sub in dependant.dependencies:
        call = sub.call
        if call is not None and not (inspect.iscoroutinefunction(call) or inspect.isasyncgenfunction(call)):
            yield f"{call.__module__}.{getattr(call, '__qualname__', call)}"
        yield from _sync_dependencies(sub)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_no_route_dependency_runs_in_the_thread_pool() -> None:
    """A plain ``def`` dependency runs in a worker thread: on a loaded machine each hop costs more than the whole
    health check (benchmarks/RESULTS.md, Request path). Blocking work belongs in the endpoint or the services."""
    app = create_app()
    routes = [context.route for context in iter_route_contexts(app.router.routes)
              if isinstance(context.route, APIRoute)]
    assert len(routes) > 100
    found = {f"{name} (in {route.path})" for route in routes for name in _sync_dependencies(route.dependant)}
    assert not found, sorted(found)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_a_server_of_its_own_freezes_what_start_up_made() -> None:
    """``drivebench serve`` (``settle_heap``): full collections then skip the objects start-up made."""
    assert gc.get_freeze_count() == 0
    try:
        with TestClient(create_app()):
            assert gc.get_freeze_count() == 0, "only a server process of its own freezes its heap"
        with TestClient(create_app(settle_heap=True)):
            assert gc.get_freeze_count() > 10_000
    finally:
        gc.unfreeze()


def test_a_server_held_from_collecting_during_its_start_collects_again_once_started() -> None:
    """``drivebench serve`` holds the cyclic collector from its first import (``heap.hold``: its passes over the
    growing heap freed nothing and cost a tenth of the start, issue 33); the settled start turns it on again."""
    heap.hold()
    try:
        assert not gc.isenabled()
        with TestClient(create_app(settle_heap=True)):
            assert gc.isenabled(), "a server left without cyclic collection would keep every cycle it makes"
    finally:
        gc.enable()
        gc.unfreeze()
