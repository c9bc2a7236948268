"""Switch SDO faults of a simulated node, and LSS faults of a simulated LSS device, on and off (demos and tests);
refused for sessions on a real bus."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path
from pydantic import BaseModel, ConfigDict, Field, field_validator

from drivebench.errors import Conflict, NotFound
from drivebench.i18n import _
from drivebench.simulator.faults import ABORT_CODE_RANGE, SdoFaults
from drivebench.simulator.lss_slave import LssDevice, LssFaults
from drivebench.simulator.node import SimulatedNode
from drivebench.simulator.plant import Plant
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep, StateDep

router = APIRouter(route_class=DeferredRoute, prefix="/api", tags=["simulator"])
FAULTS = "/sessions/{session_id}/simulator/nodes/{node_id}/faults"
NodeId = Annotated[int, Path(ge=1, le=127, description="CANopen node id")]


class FaultsIn(BaseModel):
    """The faults to switch on; fields left out are off. ``{}`` clears every fault."""

    model_config = ConfigDict(extra="forbid")

    silent_after_segments: int | None = Field(None, ge=0, le=10_000,
                                              description="Answer this many segments of a segmented transfer, "
                                                          "then stop answering until the next transfer")
    wrong_toggle: bool = Field(False, description="Answer segments with the wrong toggle bit")
    index_offset: int = Field(0, ge=-0xFFFF, le=0xFFFF, description="Answers name index + this")
    subindex_offset: int = Field(0, ge=-0xFF, le=0xFF, description="Answers name subindex + this")
    abort_code: int | str | None = Field(None, description="Abort requests with this CiA 301 code "
                                                           "(0x08000000 or 134217728)")
    abort_every: int = Field(1, ge=1, le=10_000, description="Abort every n-th request (1: every one)")
    abort_index: int | None = Field(None, ge=0, le=0xFFFF, description="Abort only requests for this object index "
                                                                      "(none: every object)")
    latency_ms: float = Field(0.0, ge=0, le=60_000, description="Extra SDO processing time")
    late_requests: int = Field(0, ge=0, le=1_000_000, description="Only the next this many requests that start "
                                                                   "a transfer get the extra time (0: every one)")
    drop_requests: int = Field(0, ge=0, le=1_000_000, description="Leave the next this many requests that start "
                                                                   "a transfer unanswered")
    drop_downloads: int = Field(0, ge=0, le=1_000_000, description="Leave the next this many download requests "
                                                                    "unanswered (uploads are answered)")
    lost_download_answers: int = Field(0, ge=0, le=1_000_000, description="Write the next this many expedited "
                                       "downloads but lose their answers (the device holds the value)")
    flash_error: int | None = Field(None, ge=1, le=127, description="The next program download (0x1F50) fails to "
                                    "flash with this CiA 302-3 flash status error code")
    power_loss_mid_flash: bool = Field(False, description="The power fails while the next program download is "
                                                          "flashed: the device comes back in its bootloader")

    @field_validator("abort_code")
    @classmethod
    def _code(cls, value: int | str | None) -> int | None:
        if value is None or isinstance(value, int):
            code = value
        else:
            try:
                code = int(value, 0)
            except ValueError as exc:
                raise ValueError(_("abort_code must be a number such as 0x08000000")) from exc
        if code is not None and not 0 < code <= 0xFFFFFFFF:
            raise ValueError(_(ABORT_CODE_RANGE))
        return code


class FaultsOut(BaseModel):
    session_id: str
    node_id: int
    faults: dict[str, object]
    active: list[str]
    """The active faults in words; empty when the node behaves."""


def _plant(state: StateDep, session: SessionDep) -> Plant:
    plant = state.plants.get(session.id)
    if not session.simulated or plant is None:
        raise Conflict(_("Session '{session}' is on a real bus: faults can be switched on simulated sessions "
                         "only").format(session=session.id))
    return plant


def _simulated_node(state: StateDep, session: SessionDep, node_id: int) -> SimulatedNode:
    node = _plant(state, session).nodes.get(node_id)
    if node is None:
        raise NotFound(_("The simulated plant of session '{session}' has no node {node}").format(
            session=session.id, node=node_id))
    return node


def _out(session_id: str, node: SimulatedNode) -> FaultsOut:
    faults = node.faults.faults
    return FaultsOut(session_id=session_id, node_id=node.node_id, faults=faults.as_dict(), active=faults.describe())


@router.get(FAULTS, response_model=FaultsOut)
async def get_faults(state: StateDep, session: SessionDep, node_id: NodeId) -> FaultsOut:
    return _out(session.id, _simulated_node(state, session, node_id))


@router.put(FAULTS, response_model=FaultsOut)
async def put_faults(state: StateDep, session: SessionDep, node_id: NodeId, body: FaultsIn) -> FaultsOut:
    """Replace the node's faults with these (``{}``: the node behaves again, at once)."""
    node = _simulated_node(state, session, node_id)
    code = body.abort_code if isinstance(body.abort_code, int) else None
    node.faults.set(SdoFaults(**{**body.model_dump(), "abort_code": code}))
    return _out(session.id, node)


@router.delete(FAULTS, response_model=FaultsOut)
async def clear_faults(state: StateDep, session: SessionDep, node_id: NodeId) -> FaultsOut:
    node = _simulated_node(state, session, node_id)
    node.faults.clear()
    return _out(session.id, node)


# --- LSS faults of a simulated LSS device (by its serial number: it may have no node ID) ----------------------
LSS_FAULTS = "/sessions/{session_id}/simulator/lss/{serial}/faults"
Serial = Annotated[int, Path(ge=0, le=0xFFFFFFFF, description="the device's serial number (0x1018 sub 4)")]


class LssFaultsIn(BaseModel):
    """The LSS faults to switch on; fields left out are off (as ``lss_faults`` in a plant file)."""

    model_config = ConfigDict(extra="forbid")

    stays_in_configuration: bool = Field(False, description="ignore switch state global (waiting): never leave "
                                                            "LSS configuration state")
    ignores_activate_bit_timing: bool = Field(False, description="ignore activate bit timing: stay at its bit rate")


class LssFaultsOut(BaseModel):
    session_id: str
    serial: str
    faults: dict[str, bool]
    active: list[str]
    """The active faults in words; empty when the device behaves."""


def _lss_device(state: StateDep, session: SessionDep, serial: int) -> LssDevice:
    device = next((device for device in _plant(state, session).lss.devices if device.slave.address[3] == serial),
                  None)
    if device is None:
        raise NotFound(_("The simulated plant of session '{session}' has no LSS device with serial {serial}").format(
            session=session.id, serial=f"0x{serial:08X}"))
    return device


def _lss_out(session_id: str, device: LssDevice) -> LssFaultsOut:
    faults = device.slave.faults
    return LssFaultsOut(session_id=session_id, serial=f"0x{device.slave.address[3]:08X}",
                        faults={"stays_in_configuration": faults.stays_in_configuration,
                                "ignores_activate_bit_timing": faults.ignores_activate_bit_timing},
                        active=faults.describe())


@router.get(LSS_FAULTS, response_model=LssFaultsOut)
async def get_lss_faults(state: StateDep, session: SessionDep, serial: Serial) -> LssFaultsOut:
    return _lss_out(session.id, _lss_device(state, session, serial))


@router.put(LSS_FAULTS, response_model=LssFaultsOut)
async def put_lss_faults(state: StateDep, session: SessionDep, serial: Serial, body: LssFaultsIn) -> LssFaultsOut:
    """Replace the device's LSS faults with these (``{}``: it behaves again; kept over a power cycle)."""
    device = _lss_device(state, session, serial)
    device.slave.faults = LssFaults(**body.model_dump())
    return _lss_out(session.id, device)
