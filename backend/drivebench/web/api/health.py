from __future__ import annotations

import asyncio
import time

from fastapi import APIRouter, Request, Response
from pydantic import BaseModel, TypeAdapter

from drivebench import __version__
from drivebench.config import settings
from drivebench.services.profiles.loading import ProfilesLoading, progress
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import StateDep
from drivebench.web.lean_route import lean_route
from drivebench.web.state import AppState, app_state

router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["health"])
_STARTED = time.time()


class Health(BaseModel):
    status: str
    """``ok``: the server serves (its buses and sessions); the database is reported on its own."""
    version: str
    uptime_s: float
    sessions: int
    database: str
    """``ok`` or ``unreachable`` (sign-in, sets, audit log and users then answer 503; buses still work)."""
    database_reason: str | None = None
    profiles: ProfilesLoading
    """The stored uploads: ``loading`` while a worker thread reads them after start; ``status`` stays ``ok`` (the
    server serves: the shipped profiles, the sessions and every upload read so far)."""


async def _answer(state: AppState) -> Health:
    """The database's answer at most ``RecentProbes.every_s`` old; a worker thread only when it is older (a poll
    stays cheap, a database that does not answer never holds the event loop)."""
    url = settings.database_url
    fresh, failure = state.database_probes.recent(url)
    if not fresh:
        failure = await asyncio.to_thread(state.database_probes.failure, url)
    return Health(status="ok", version=__version__, uptime_s=round(time.time() - _STARTED, 1),
                  sessions=len(state.manager.list()), database="ok" if failure is None else "unreachable",
                  database_reason=None if failure is None else failure.shown_detail(),
                  profiles=progress(state.registry))


async def health(state: StateDep) -> Health:
    """Answers without touching the bus; the database's answer is at most two seconds old."""
    return await _answer(state)


_HEALTH_JSON = TypeAdapter(Health)


async def _lean_health(request: Request) -> Response:
    """The same answer without FastAPI's dependency solving: the check load balancers and monitors poll."""
    state = app_state(request.app)
    return Response(_HEALTH_JSON.dump_json(await _answer(state), by_alias=True),
                    media_type="application/json")


router.add_api_route("/health", health, methods=["GET"], response_model=Health,
                     route_class_override=lean_route(_lean_health))
