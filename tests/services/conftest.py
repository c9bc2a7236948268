"""Fixtures of the service tests: a session on the demo plant, driven by its own event loop runner."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.bus.sessions import Session
from drivebench.services.params import parameters
from drivebench.services.params.parameters import WriteResult
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant
from tests.write_contexts import SERVICE


@pytest.fixture
def plant_session(request: pytest.FixtureRequest, plant: Plant,
                  registry: ProfileRegistry) -> Iterator[tuple[asyncio.Runner, Session]]:
    """A session on the demo plant with its nodes, as the server opens one (SDO timeout 1 s, one retry)."""
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    session = runner.run(manager.open(plant.spec, request.module.__name__.rsplit(".", 1)[-1]))
    for node in plant.nodes.values():
        session.add_node(node.node_id, node.profile.id)
    try:
        yield runner, session
    finally:
        runner.run(manager.close_all())
        runner.close()


async def set_up(session: Session, node_id: int, ref: str, value: object, **options: bool) -> WriteResult:
    """A test's set-up write (command source, a drive run the test measures) as a caller that confirmed it itself
    (:meth:`WriteContext.cleared_by_caller`): it needs no confirmation and arms nothing."""
    return await parameters.write(session, node_id, ref, value, ctx=SERVICE.cleared_by_caller(), **options)
