"""Drive control panel API: status (state machine, named bits), transitions, setpoint, jog, modes, actual values,
keep-alive, and the guided commissioning runs. Commands that can make the motor turn need ``"confirm": <node id>``
and ``"confirm_values"``: the values the 428 problem named (or the headers ``X-DriveBench-Confirm: <node id>`` and
``X-DriveBench-Confirm-Values: <JSON object>``); without them, or with other values, they answer 428.

A panel names itself with the headers ``X-Drive-Panel`` or ``X-DriveBench-Client`` (an id, one per browser tab) and
``X-Drive-Operator`` (the name other panels are shown; else the signed-in user); without them the client is one panel
per host. The panel that armed a drive holds it: other panels get 409 for anything but stopping it (see
``services.drive_control``), and the node's write lease is the holder's (``services.node_lease``).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field

from drivebench.services.control import commissioning, drive_control, motion
from drivebench.services.control.commissioning import RunOut
from drivebench.services.control.drive_control import ActualValue, DriveStatus, JogPlan
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.control.drive_words import Command
from drivebench.services.control.motion import CyclicStream, MotionInfo
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import NodeDep, SessionDep
from drivebench.web.safety import PanelDep, WriteCtxDep, confirmation

router = APIRouter(prefix="/api/sessions/{session_id}/nodes/{node_id}/control", tags=["drive control"],
                   responses={428: {"description": "Not confirmed with the node id"}}, route_class=DeferredRoute)


class Confirmed(BaseModel):
    confirm: int | str | None = Field(None, description="The node id, for commands after which the motor may turn "
                                                        "(or the header X-DriveBench-Confirm)")
    confirm_values: dict[str, Any] | None = Field(None, description="The values the 428 named (confirm_values), "
                                                                    "repeated (or the header "
                                                                    "X-DriveBench-Confirm-Values)")


def _given(request: Request, body: Confirmed | None) -> Confirmation | None:
    return confirmation(request, body and body.confirm, body and body.confirm_values)


class StepIn(Confirmed):
    value: float | int | str | None = Field(None, description="A parameter step's value in the parameter's units "
                                                              "(else the profile's proposal)")


class SetpointIn(Confirmed):
    value: float = Field(description="Setpoint in the unit the status names (rpm, Hz, %, permille)")


class JogIn(Confirmed):
    direction: int = Field(ge=-1, le=1, description="1 forward, -1 reverse, 0 stop")
    speed: float | None = Field(None, gt=0, description="CiA 402 profile-velocity jog: the speed in the drive's "
                                                         "velocity units (at most 0x607F)")


class MoveIn(Confirmed):
    target: float = Field(description="Target position 0x607A in the drive's position units")
    relative: bool = Field(False, description="Control word bit 6: relative to the last target")
    immediate: bool = Field(True, description="Control word bit 5: change set immediately")
    velocity: float | None = Field(None, gt=0, description="Profile velocity 0x6081 (velocity units)")


class CyclicIn(Confirmed):
    value: float = Field(description="Target of the mode shown (7: interpolation data record 0x60C1.1, 8: 0x607A, "
                                     "9: 0x60FF, 10: 0x6071)")


class StoppedOut(BaseModel):
    stopped: int = Field(description="Cyclic RPDOs to the node that were running")


class HomeIn(Confirmed):
    method: int = Field(description="Homing method 0x6098 (CiA 402: 1 ... 14, 17 ... 30, 33 ... 35, 37; where the "
                                    "drive has 0x60E3, one it lists there)")


class ModeIn(Confirmed):
    mode: int = Field(description="0x6060 modes of operation, as the status lists them in modes")


class KeepaliveOut(BaseModel):
    armed: bool = Field(description="This panel holds the armed node and its keep-alive restarted the deadline")
    holder: str | None = Field(None, description="Who holds the armed node, and since when")


class SequenceOut(BaseModel):
    key: str
    title: str
    source: str
    preconditions: list[str]
    missing: list[str]
    steps: int


@router.get("", response_model=DriveStatus)
async def status(session: SessionDep, node: NodeDep, panel: PanelDep) -> DriveStatus:
    """State from the status word, every control and status bit named, the commands, setpoint range and holder."""
    return await drive_control.read_status(session, node, panel)


@router.post("/commands/{command}", response_model=DriveStatus)
async def command(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, command: Command,
                  body: Confirmed | None = None) -> DriveStatus:
    return await drive_control.command(session, node, command, ctx=ctx, confirm=_given(request, body),
                                       panel=panel)


@router.put("/setpoint", response_model=DriveStatus)
async def setpoint(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep, ctx: WriteCtxDep,
                   body: SetpointIn) -> DriveStatus:
    return await drive_control.set_setpoint(session, node, body.value, ctx=ctx, confirm=_given(request, body),
                                            panel=panel)


@router.get("/jog", response_model=JogPlan)
async def jog_plan(session: SessionDep, node: NodeDep) -> JogPlan:
    """How this device jogs: its own jog function (8200 vector: JOG1 by control word bits) or a setpoint."""
    return await drive_control.jog_plan(session, node)


@router.post("/jog", response_model=DriveStatus)
async def jog(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, body: JogIn) -> DriveStatus:
    return await drive_control.jog(session, node, body.direction, ctx=ctx, confirm=_given(request, body),
                                   panel=panel, speed=body.speed)


@router.get("/motion", response_model=MotionInfo)
async def motion_info(session: SessionDep, node: NodeDep) -> MotionInfo:
    """CiA 402 drive without a vendor control section: units, quick stop option, profile and homing settings."""
    return await motion.info(session, node)


@router.post("/move", response_model=DriveStatus)
async def move(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, body: MoveIn) -> DriveStatus:
    """CiA 402 profile-position move (mode 1): target, new set-point edge, set-point acknowledge."""
    return await motion.move(session, node, body.target, relative=body.relative, immediate=body.immediate,
                             velocity=body.velocity, ctx=ctx, confirm=_given(request, body), panel=panel)


@router.post("/cyclic", response_model=CyclicStream)
async def cyclic(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep, body: CyclicIn) -> CyclicStream:
    """Interpolated position (7) or cyclic synchronous mode (8/9/10): SYNC at 0x60C2 and an RPDO with the control
    word and the target, every cycle, while this panel holds the drive (any stopping command or a lost keep-alive
    ends it)."""
    return await motion.stream(session, node, body.value, confirm=_given(request, body), panel=panel)


@router.delete("/cyclic", response_model=StoppedOut)
async def stop_cyclic(session: SessionDep, node: NodeDep) -> StoppedOut:
    return StoppedOut(stopped=motion.stop_stream(session, node))


@router.post("/home", response_model=DriveStatus)
async def home(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, body: HomeIn) -> DriveStatus:
    """CiA 402 homing (mode 6) with the method given; status bit 12 homing attained, bit 13 homing error."""
    return await motion.home(session, node, body.method, ctx=ctx, confirm=_given(request, body), panel=panel)


@router.put("/mode", response_model=DriveStatus)
async def mode(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, body: ModeIn) -> DriveStatus:
    return await drive_control.set_mode(session, node, body.mode, ctx=ctx, confirm=_given(request, body),
                                        panel=panel)


@router.get("/actuals", response_model=list[ActualValue])
async def actuals(session: SessionDep, node: NodeDep) -> list[ActualValue]:
    return await drive_control.read_actuals(session, node)


@router.post("/keepalive", response_model=KeepaliveOut)
async def keepalive(session: SessionDep, node: NodeDep, panel: PanelDep) -> KeepaliveOut:
    """While this panel holds the armed node, send this at least every 2 s, or the server sends quick stop."""
    guard = drive_control.guard_for(session)
    holder = guard.holder(node.node_id)
    return KeepaliveOut(armed=guard.keepalive(node.node_id, panel), holder=holder.text() if holder else None)


@router.get("/sequences", response_model=list[SequenceOut])
async def sequences(node: NodeDep) -> list[SequenceOut]:
    return [SequenceOut(key=seq.key, title=seq.title, source=seq.source, preconditions=list(seq.preconditions),
                        missing=list(seq.missing), steps=len(seq.steps)) for seq in commissioning.sequences_for(node)]


@router.post("/sequences/{key}/runs", response_model=RunOut, status_code=201)
async def start_run(session: SessionDep, node: NodeDep, key: str, ctx: WriteCtxDep) -> RunOut:
    """Start a run for this node; it takes the node's write lease (409 while another writer holds it) and belongs
    to this writer (principal and panel)."""
    return commissioning.wizard(session).start(session, node, key, ctx).public(node)


@router.get("/runs", response_model=list[RunOut])
async def runs(session: SessionDep, node: NodeDep) -> list[RunOut]:
    """The node's commissioning runs, the latest first: a reloaded page shows where the last one stands."""
    return [run.public(node) for run in commissioning.wizard(session).of_node(node.node_id)]


@router.get("/runs/{run_id}", response_model=RunOut)
async def get_run(session: SessionDep, node: NodeDep, run_id: str) -> RunOut:
    return commissioning.wizard(session).get(run_id, node.node_id).public(node)


@router.post("/runs/{run_id}/next", response_model=RunOut)
async def next_step(request: Request, session: SessionDep, node: NodeDep, panel: PanelDep,
                  ctx: WriteCtxDep, run_id: str,
                    body: StepIn | None = None) -> RunOut:
    """Run the next step of a run of this node, started by this writer (404 for another node's run, 409 for another
    writer's); a step that can turn the motor needs the confirmation naming the node and the values the step sends;
    a step value outside the profile's range is refused (422) before anything is sent."""
    run = commissioning.wizard(session).get(run_id, node.node_id)
    await commissioning.next_step(session, node, run, ctx=ctx, confirm=_given(request, body), panel=panel,
                                  value=body.value if body is not None else None)
    return run.public(node)
