"""Dependencies shared by routes: the session manager, a session, a node (resolved once).

They only look things up in memory, so they are ``async``: a plain ``def`` dependency would run in the thread pool,
a thread hop per dependency on every request (benchmarks/RESULTS.md, Request path)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Query, Request

from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params.jobs import JobManager
from drivebench.services.profiles import loading as profiles_loading
from drivebench.services.session_manager import SessionManager
from drivebench.web.root import root_of
from drivebench.web.state import AppState, app_state


async def get_state(request: Request) -> AppState:
    state = app_state(request.app)
    return state


StateDep = Annotated[AppState, Depends(get_state)]


async def get_manager(state: StateDep) -> SessionManager:
    return state.manager


ManagerDep = Annotated[SessionManager, Depends(get_manager)]


async def get_session(request: Request, session_id: Annotated[str, Path(description="Session id")]) -> Session:
    """The session, looked up directly (not through StateDep and ManagerDep: each dependency level costs a request
    some microseconds, and every node route has this one; benchmarks/RESULTS.md, Request path)."""
    state = app_state(request.app)
    return state.manager.get(session_id)


SessionDep = Annotated[Session, Depends(get_session)]


async def get_node(session: SessionDep, node_id: Annotated[int, Path(ge=1, le=127, description="CANopen node id")]
             ) -> SessionNode:
    return session.node(node_id)


NodeDep = Annotated[SessionNode, Depends(get_node)]

MAX_ROW_ID = 2**31 - 1
"""The largest id a database row can have (INTEGER on PostgreSQL; SQLite fails past 2**63): larger ones -> 422."""
RowId = Annotated[int, Path(ge=1, le=MAX_ROW_ID, description="Database id")]
RowVersion = Annotated[int | None, Query(ge=1, le=MAX_ROW_ID, description="Version (newest when left out)")]


async def get_jobs(request: Request) -> JobManager:
    return app_state(request.app).jobs


JobsDep = Annotated[JobManager, Depends(get_jobs)]


async def get_root(request: Request) -> str:
    """The sub-path the server is reached under (web/root.py), for the URLs an answer names."""
    return root_of(request.scope)


RootDep = Annotated[str, Depends(get_root)]


async def wait_for_profiles(request: Request) -> None:
    """Profile routes wait for the stored uploads (loaded in the background after start, issue 33) when their
    ``profile_id`` is not known yet, and a change (upload, delete) waits for all of them; lists do not wait."""
    registry = app_state(request.app).registry
    if request.method not in ("GET", "HEAD"):
        await profiles_loading.uploads_loaded(registry)
    else:
        await profiles_loading.profiles_known(registry, [request.path_params.get("profile_id")])
