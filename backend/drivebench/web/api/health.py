from __future__ import annotations

import time

from fastapi import APIRouter
from pydantic import BaseModel

from drivebench import __version__
from drivebench.web.deps import StateDep

router = APIRouter(prefix="/api", tags=["health"])
_STARTED = time.time()


class Health(BaseModel):
    status: str
    version: str
    uptime_s: float
    sessions: int


@router.get("/health", response_model=Health)
async def health(state: StateDep) -> Health:
    """Answers from the event loop without touching the bus."""
    return Health(status="ok", version=__version__, uptime_s=round(time.time() - _STARTED, 1),
                  sessions=len(state.manager.list()))
