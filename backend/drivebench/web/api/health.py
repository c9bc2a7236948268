from __future__ import annotations

import time

from fastapi import APIRouter, Request, Response
from pydantic import BaseModel, TypeAdapter

from drivebench import __version__
from drivebench.services.session_manager import SessionManager
from drivebench.web.deps import StateDep
from drivebench.web.lean_route import lean_route
from drivebench.web.state import AppState

router = APIRouter(prefix="/api", tags=["health"])
_STARTED = time.time()


class Health(BaseModel):
    status: str
    version: str
    uptime_s: float
    sessions: int


def _answer(manager: SessionManager) -> Health:
    return Health(status="ok", version=__version__, uptime_s=round(time.time() - _STARTED, 1),
                  sessions=len(manager.list()))


async def health(state: StateDep) -> Health:
    """Answers from the event loop without touching the bus."""
    return _answer(state.manager)


_HEALTH_JSON = TypeAdapter(Health)


async def _lean_health(request: Request) -> Response:
    """The same answer without FastAPI's dependency solving: the check load balancers and monitors poll."""
    state: AppState = request.app.state.drivebench
    return Response(_HEALTH_JSON.dump_json(_answer(state.manager), by_alias=True), media_type="application/json")


router.add_api_route("/health", health, methods=["GET"], response_model=Health,
                     route_class_override=lean_route(_lean_health))
