"""Progress of a long job (read-all ...), pushed while it runs.

Message (JSON, one per change, at most ten a second, and a last one when the job has finished)::

    {"id": "read-3-ab12cd", "state": "running", "title": "Read all parameters of node 5",
     "progress": {"done": 120, "total": 160, "failed": 0, "rate_per_s": 35.1, "eta_s": 1.1, "elapsed_s": 3.4},
     "notes": ["SDO2 activated on node 5 (0x645/0x5C5, not saved)"], "issues": 0, "error": null}

The socket closes (code 1000) after the final message; an unknown job closes it with code 4404.
"""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket

from drivebench.errors import NotFound
from drivebench.i18n import shown
from drivebench.services.params.jobs import Job
from drivebench.web.state import app_state
from drivebench.web.ws.node_socket import serve

router = APIRouter()
MIN_INTERVAL_S = 0.1


def message(job: Job) -> dict[str, object]:
    return {"id": job.id, "state": job.state.value, "title": shown(job.title), "progress": job.progress().model_dump(),
            "notes": [shown(note) for note in job.notes], "issues": len(job.issues),
            "error": job.error and shown(job.error)}


@router.websocket("/ws/jobs/{job_id}")
async def job_progress(websocket: WebSocket, job_id: str) -> None:
    await websocket.accept()
    try:
        job = app_state(websocket.app).jobs.get(job_id)
    except NotFound as exc:
        await websocket.close(code=4404, reason=exc.detail[:120])
        return

    async def receive() -> None:  # nothing is expected: it notices the client leaving while the job is unchanged
        while True:
            await websocket.receive_text()

    async def send() -> None:
        version = -1
        while True:
            if job.version != version or job.state.finished:
                version = job.version
                await websocket.send_json(message(job))
            if job.state.finished:
                await websocket.close()
                return
            await asyncio.sleep(MIN_INTERVAL_S)
            await job.wait_change(version, timeout_s=1.0)

    await serve(receive(), send())
