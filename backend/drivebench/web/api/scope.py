"""The oscilloscope: channels to pick, a recording of a session (start, state, stop), stored recordings (list, open,
export CSV/JSON, delete)."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, Field

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.scope import export, runs, store
from drivebench.services.scope.channels import MAX_CHANNELS, candidates
from drivebench.services.scope.source import ScopeChannel
from drivebench.services.scope.trigger import TriggerSpec
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep
from drivebench.web.identity import principal_of
from drivebench.web.safety import WriteCtxDep, confirmation

router = APIRouter(route_class=DeferredRoute, tags=["scope"])
RecordingId = Annotated[int, Path(ge=1, le=2**31 - 1, description="A stored recording's id")]
S = "/api/sessions/{session_id}/scope"


class ChannelBody(BaseModel):
    node: int = Field(ge=1, le=127)
    ref: str = Field(min_length=1, max_length=40)
    bit: int | None = Field(default=None, ge=0, le=63)


class TriggerBody(BaseModel):
    mode: Literal["free", "single", "normal"] = "single"
    on: Literal["level", "emcy", "nmt"] = "level"
    channel: int = Field(default=0, ge=0, lt=MAX_CHANNELS, description="Position of the channel in `channels`")
    edge: Literal["rising", "falling"] = "rising"
    level: float = 0.0
    node: int | None = Field(default=None, ge=1, le=127, description="EMCY/NMT: only this node's")
    pre_percent: float = Field(default=0.0, ge=0, le=100)


class StartBody(BaseModel):
    channels: list[ChannelBody] = Field(min_length=1, max_length=MAX_CHANNELS)
    period_ms: float = Field(default=100.0, gt=0)
    length_samples: int | None = Field(default=None, ge=2)
    length_s: float | None = Field(default=None, gt=0)
    trigger: TriggerBody = Field(default_factory=TriggerBody)
    name: str = Field(default="", max_length=200)
    max_s: float = Field(default=runs.DEFAULT_MAX_S, gt=0, le=runs.MAX_MAX_S, description=(
        "How long the recording runs while no page of its owner watches it (the Scope page, a Control tab's scope "
        "panel): a recording started over the API ends by itself after this, stores what it captured and puts "
        "the nodes back; a page's recording runs on while the page is open."))
    confirm: Any = None
    confirm_values: Any = None

    def request(self) -> runs.StartRequest:
        if (self.length_samples is None) == (self.length_s is None):
            raise InvalidValue(_("Give the length either in samples (length_samples) or in seconds (length_s), "
                                 "one of the two."))
        period_s = self.period_ms / 1000
        length = self.length_samples or max(2, round((self.length_s or 0) / period_s))
        spec = TriggerSpec(self.trigger.mode, self.trigger.on, self.trigger.channel, self.trigger.edge,
                           self.trigger.level, self.trigger.pre_percent, length, self.trigger.node)
        channels = [ScopeChannel(c.node, c.ref, c.bit) for c in self.channels]
        return runs.StartRequest(channels, period_s, spec, self.name, self.max_s)


@router.get(S + "/channels")
async def channels(session: SessionDep, node: Annotated[int, Query(ge=1, le=127)],
                   q: Annotated[str, Query(max_length=80)] = "") -> list[dict[str, Any]]:
    """What a node offers as channels (its PDO-mappable objects and the control section's actual values),
    filtered by a part of the name, code or index."""
    return [{"node": c.node, "ref": c.ref, "name": c.name, "unit": c.unit, "index": f"0x{c.index:04X}",
             "subindex": c.subindex, "bits": c.bits} for c in candidates(session, node, q)]


@router.post(S + "/run", status_code=201)
async def start(session: SessionDep, body: StartBody, request: Request, ctx: WriteCtxDep) -> dict[str, Any]:
    """Start a recording (engineer). Polling moves nothing; a source that starts nodes or SYNC asks for the
    confirmation (428 with ``confirm_node`` and ``confirm_values``). With no page of the starter watching, the
    recording ends by itself after ``max_s`` (default 600 s) and puts the nodes back."""
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    run = await runs.start(session, body.request(), principal_of(request).name, ctx)
    return run.status()


@router.get(S + "/run")
async def state(session: SessionDep) -> dict[str, Any]:
    """The session's recording: running, or the last one since the server started."""
    return runs.current(session).status()


@router.post(S + "/run/stop")
async def stop(session: SessionDep) -> dict[str, Any]:
    """Stop the recording; what it captured is stored (``recording_id``)."""
    return (await runs.stop(session)).status()


@router.get("/api/scope/recordings")
async def recordings() -> list[dict[str, Any]]:
    return await asyncio.to_thread(store.listing)


@router.get("/api/scope/recordings/{recording_id}")
async def recording(recording_id: RecordingId) -> dict[str, Any]:
    """A stored recording with its samples by column (``values[channel][sample]``, null: the node sent nothing)."""
    return (await asyncio.to_thread(store.load, recording_id)).as_json()


@router.get("/api/scope/recordings/{recording_id}/export")
async def export_recording(recording_id: RecordingId, format: Literal["csv", "json"] = "csv") -> Response:
    found = await asyncio.to_thread(store.load, recording_id)
    text = export.to_csv(found) if format == "csv" else export.to_json(found)
    media = "text/csv" if format == "csv" else "application/json"
    return Response(text, media_type=f"{media}; charset=utf-8", headers={
        "Content-Disposition": f'attachment; filename="{export.file_name(found, format)}"'})


@router.delete("/api/scope/recordings/{recording_id}", status_code=204)
async def delete(recording_id: RecordingId) -> Response:
    await asyncio.to_thread(store.remove, recording_id)
    return Response(status_code=204)

