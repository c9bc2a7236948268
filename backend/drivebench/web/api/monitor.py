"""The telegram monitor of a session: counters and load, trace, filter, pause/reset, recordings, device counters.

Counters, load history and the trace ring are shared by everyone watching the session, and ``/reset`` clears them
for all. Filter and pause here are the session's *default view*: what this REST API's snapshot and trace show, and
what a websocket client starts with. A connected websocket client changes its own view over its socket (see
``web/ws/monitor.py``); these endpoints never change another viewer's filter or pause.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query
from fastapi.responses import FileResponse
from pydantic import BaseModel

from drivebench.services.monitoring import telegram_counters
from drivebench.services.monitoring.monitor import MonitorFilter, monitor_for
from drivebench.services.monitoring.recording import MEDIA_TYPES, format_names, recordings_for
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep
from drivebench.web.monitor_filter import FilterBody

router = APIRouter(route_class=DeferredRoute, prefix="/api/sessions/{session_id}/monitor", tags=["monitor"])

FormatName = Literal["pcapng", "log", "asc", "blf", "trc", "csv"]


class RecordingStart(BaseModel):
    format: FormatName = "pcapng"


@router.get("")
async def snapshot(session: SessionDep, trace: Annotated[int, Query(ge=0, le=1000)] = 100) -> dict[str, Any]:
    """Counters per service, node and COB-ID (total and rate), errors, load with peak, the newest trace rows."""
    monitor = monitor_for(session)
    return {**monitor.snapshot(), "trace": monitor.trace_rows(limit=trace) if trace else []}


@router.get("/trace")
async def trace(session: SessionDep, after: Annotated[int, Query(ge=0)] = 0,
                limit: Annotated[int, Query(ge=1, le=10_000)] = 200) -> dict[str, Any]:
    """Decoded telegrams after sequence number ``after`` (oldest first); ``next`` is the ``after`` for next time."""
    rows, newest = monitor_for(session).trace_since(after, limit)
    return {"rows": rows, "next": newest}


@router.get("/history")
async def history(session: SessionDep) -> dict[str, Any]:
    """Bus load of each completed second of the last 10 minutes: ``[wall time, percent]``."""
    monitor = monitor_for(session)
    return {"bitrate": monitor.bitrate, "points": monitor.history()}


@router.post("/reset")
async def reset(session: SessionDep) -> dict[str, Any]:
    monitor = monitor_for(session)
    monitor.reset()
    return monitor.snapshot()


@router.post("/pause")
async def pause(session: SessionDep) -> dict[str, bool]:
    """Freeze the default view (REST snapshot and trace, new viewers); counting goes on underneath."""
    monitor = monitor_for(session)
    monitor.pause()
    return {"paused": monitor.paused}


@router.post("/resume")
async def resume(session: SessionDep) -> dict[str, bool]:
    monitor = monitor_for(session)
    monitor.resume()
    return {"paused": monitor.paused}


@router.get("/filter", response_model=FilterBody)
async def get_filter(session: SessionDep) -> dict[str, Any]:
    """The default filter: of the REST snapshot and trace, and the one a new websocket viewer starts with."""
    return monitor_for(session).filter.as_dict()


@router.put("/filter", response_model=FilterBody)
async def set_filter(session: SessionDep, body: FilterBody) -> dict[str, Any]:
    """Set the default filter (REST snapshot and trace, new viewers); connected viewers keep theirs."""
    monitor = monitor_for(session)
    monitor.set_filter(MonitorFilter(set(body.nodes), set(body.services), body.cob_min, body.cob_max))
    return monitor.filter.as_dict()


@router.get("/recordings")
async def list_recordings(session: SessionDep) -> dict[str, Any]:
    recordings = recordings_for(session)
    return {"formats": format_names(), "recordings": [info.as_dict() for info in recordings.list()]}


@router.post("/recordings", status_code=201)
async def start_recording(session: SessionDep, body: RecordingStart) -> dict[str, Any]:
    recorder = recordings_for(session).start(body.format)
    return {"name": recorder.path.name, "format": recorder.format, "started": recorder.started}


@router.post("/recordings/stop")
async def stop_recording(session: SessionDep) -> dict[str, Any]:
    recorder = recordings_for(session).stop()
    return {"name": recorder.path.name, "format": recorder.format, "frames": recorder.frames}


@router.get("/recordings/{name}")
async def download_recording(session: SessionDep, name: Annotated[str, Path(max_length=200)]) -> FileResponse:
    path = recordings_for(session).path(name)
    return FileResponse(path, media_type=MEDIA_TYPES[path.suffix.lstrip(".")], filename=path.name)


@router.get("/device-counters/{node_id}")
async def device_counters(session: SessionDep, node_id: Annotated[int, Path(ge=1, le=127)]) -> dict[str, Any]:
    """The node's own telegram counters (read via SDO now) beside the monitor's counts for the same COB-IDs."""
    return await telegram_counters.compare(session, monitor_for(session), node_id)
