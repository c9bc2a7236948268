from __future__ import annotations

import asyncio
import threading
import time

from fastapi import APIRouter, Request, Response
from pydantic import BaseModel, TypeAdapter

from drivebench import __version__
from drivebench.config import settings
from drivebench.errors import DatabaseUnavailable
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage import reachability
from drivebench.web.deps import StateDep
from drivebench.web.lean_route import lean_route
from drivebench.web.state import app_state

router = APIRouter(prefix="/api", tags=["health"])
_STARTED = time.time()
_PROBE_EVERY_S = 2.0


class Health(BaseModel):
    status: str
    """``ok``: the server serves (its buses and sessions); the database is reported on its own."""
    version: str
    uptime_s: float
    sessions: int
    database: str
    """``ok`` or ``unreachable`` (sign-in, sets, audit log and users then answer 503; buses still work)."""
    database_reason: str | None = None


_probes: dict[str, tuple[float, DatabaseUnavailable | None]] = {}
_probe_lock = threading.Lock()


def _database_failure() -> DatabaseUnavailable | None:
    """The database asked at most every ``_PROBE_EVERY_S`` (monitors poll health once a second, or more), one
    query at a time, in a worker thread: a database that does not answer never holds the event loop."""
    url = settings.database_url
    with _probe_lock:
        at, failure = _probes.get(url, (-_PROBE_EVERY_S, None))
        if time.monotonic() - at >= _PROBE_EVERY_S:
            failure = reachability.probe(url)
            _probes[url] = (time.monotonic(), failure)
        return failure


async def _answer(manager: SessionManager) -> Health:
    url = settings.database_url
    at, failure = _probes.get(url, (-_PROBE_EVERY_S, None))
    if time.monotonic() - at >= _PROBE_EVERY_S:  # a thread only when the answer is old: a poll stays cheap
        failure = await asyncio.to_thread(_database_failure)
    return Health(status="ok", version=__version__, uptime_s=round(time.time() - _STARTED, 1),
                  sessions=len(manager.list()), database="ok" if failure is None else "unreachable",
                  database_reason=None if failure is None else failure.shown_detail())


async def health(state: StateDep) -> Health:
    """Answers without touching the bus; the database's answer is at most two seconds old."""
    return await _answer(state.manager)


_HEALTH_JSON = TypeAdapter(Health)


async def _lean_health(request: Request) -> Response:
    """The same answer without FastAPI's dependency solving: the check load balancers and monitors poll."""
    state = app_state(request.app)
    return Response(_HEALTH_JSON.dump_json(await _answer(state.manager), by_alias=True),
                    media_type="application/json")


router.add_api_route("/health", health, methods=["GET"], response_model=Health,
                     route_class_override=lean_route(_lean_health))
