"""Dependencies shared by routes: the session manager, a session, a node (resolved once)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Query, Request

from drivebench.services.sessions import Session, SessionManager, SessionNode
from drivebench.web.state import AppState


def get_state(request: Request) -> AppState:
    state: AppState = request.app.state.drivebench
    return state


StateDep = Annotated[AppState, Depends(get_state)]


def get_manager(state: StateDep) -> SessionManager:
    return state.manager


ManagerDep = Annotated[SessionManager, Depends(get_manager)]


def get_session(manager: ManagerDep, session_id: Annotated[str, Path(description="Session id")]) -> Session:
    return manager.get(session_id)


SessionDep = Annotated[Session, Depends(get_session)]


def get_node(session: SessionDep, node_id: Annotated[int, Path(ge=1, le=127, description="CANopen node id")]
             ) -> SessionNode:
    return session.node(node_id)


NodeDep = Annotated[SessionNode, Depends(get_node)]

MAX_ROW_ID = 2**31 - 1
"""The largest id a database row can have (INTEGER on PostgreSQL; SQLite fails past 2**63): larger ones -> 422."""
RowId = Annotated[int, Path(ge=1, le=MAX_ROW_ID, description="Database id")]
RowVersion = Annotated[int | None, Query(ge=1, le=MAX_ROW_ID, description="Version (newest when left out)")]
