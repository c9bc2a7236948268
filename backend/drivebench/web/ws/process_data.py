"""Live process data of one node: its mapped PDOs decoded and scaled, as they pass on the bus.

``/ws/sessions/{session}/nodes/{node}/process-data`` sends JSON messages:

* ``{"type": "hello", "client_id": "3f2a...", "node_id": 3, "pdos": [{"direction": "tpdo", "number": 5,
  "cob_id": 643, "signals": [{"ref": "0x6041", "name": "Status word", "unit": null}]}]}`` first, and again after
  the client sends ``{"cmd": "reload"}`` (the mapping was changed). ``client_id`` owns the cyclic RPDOs the page
  starts: they stop when this socket closes.
* ``{"type": "samples", "samples": [Sample ...]}`` at most ten a second, the newest frame per COB-ID
  (``drivebench.services.pdos.process_data.Sample``: node_id, direction, number, cob_id, data, t, signals with
  raw/value/unit/text).
* ``{"type": "state", "nmt_state": "Operational", "sync_period_ms": null, "cyclic": [771]}`` once a second.
* ``{"type": "error", "detail": "..."}`` when the PDOs cannot be read; the socket stays open for a reload.

An unknown session or node closes the socket with code 4404.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
import uuid

from fastapi import APIRouter, WebSocket

from drivebench.errors import DriveBenchError
from drivebench.services.bus.sessions import Session
from drivebench.services.pdos import process_data as live
from drivebench.web.ws.node_socket import open_node, serve

router = APIRouter()
MIN_INTERVAL_S = 0.1
STATE_INTERVAL_S = 1.0


async def _hello(websocket: WebSocket, session: Session, node_id: int, owner: str) -> None:
    service = live.service(session)
    try:
        await service.load(node_id)
    except DriveBenchError as exc:
        await websocket.send_json({"type": "error", "detail": exc.shown_detail()})
    pdos = [{"direction": lay.config.direction, "number": lay.config.number, "cob_id": lay.config.cob_id,
             "signals": [{"ref": ref, "name": name, "unit": entry.unit if entry else None}
                         for ref, name, entry, _ in lay.entries]}
            for lay in service.layouts.values() if lay.node_id == node_id]
    await websocket.send_json({"type": "hello", "client_id": owner, "node_id": node_id, "pdos": pdos})


def _state(session: Session, node_id: int) -> dict[str, object]:
    service = live.service(session)
    mine = {lay.config.cob_id for lay in service.layouts.values() if lay.node_id == node_id}
    return {"type": "state", "nmt_state": session.nmt_state(node_id)[0], "sync_period_ms": service.sync_period_ms,
            "cyclic": sorted(service.cyclic_cob_ids() & mine)}


@router.websocket("/ws/sessions/{session_id}/nodes/{node_id}/process-data")
async def process_data(websocket: WebSocket, session_id: str, node_id: int) -> None:
    if (opened := await open_node(websocket, session_id, node_id)) is None:
        return
    session, _node = opened
    owner = uuid.uuid4().hex
    service = live.service(session)
    watcher = service.watch(owner)

    async def receive() -> None:
        while True:
            message = await websocket.receive_json()
            if isinstance(message, dict) and message.get("cmd") == "reload":
                await _hello(websocket, session, node_id, owner)

    async def send() -> None:
        await _hello(websocket, session, node_id, owner)
        state_at = 0.0
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(watcher.wake.wait(), STATE_INTERVAL_S)
            samples = [s.model_dump(mode="json") for s in watcher.take() if s.node_id == node_id]
            if samples:
                await websocket.send_json({"type": "samples", "samples": samples})
            if time.monotonic() - state_at >= STATE_INTERVAL_S:
                state_at = time.monotonic()
                await websocket.send_json(_state(session, node_id))
            await asyncio.sleep(MIN_INTERVAL_S)

    try:
        await serve(receive(), send())
    finally:
        service.unwatch(owner)  # cyclic RPDOs of this browser stop here
