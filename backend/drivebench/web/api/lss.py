"""Line addressing (LSS, CiA 305) on a session's bus: fastscan, assign a node ID to a found device, and the steps
that reach every device (confirmation naming ``all``, refused while a node is enabled or armed)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field, field_validator

from drivebench.i18n import _
from drivebench.protocol.canopen.lss import LssAddress
from drivebench.services.lss import line as lss
from drivebench.web.deps import SessionDep
from drivebench.web.safety import WriteCtxDep, confirmation

router = APIRouter(prefix="/api/sessions/{session_id}/lss", tags=["lss"])


class Confirmed(BaseModel):
    confirm: str | int | None = Field(None, description="'all' (these steps reach every device on the bus), or the "
                                                        "X-DriveBench-Confirm header")
    confirm_values: dict[str, Any] | None = Field(None, description="the values the 428 named, repeated")


class FastscanIn(Confirmed):
    window_ms: float = Field(50, description="how long an answer is waited for (the fastscan narrows it to a few "
                                             "times the answer time it measures)")


class DeviceOut(BaseModel):
    vendor: str
    product: str
    revision: str
    serial: str
    device: str | None = Field(None, description="the profile the vendor ID and product code match, if any")
    node_id: int | None = Field(None, description="the node ID this tool gave it, once assigned")


class FastscanOut(BaseModel):
    devices: list[DeviceOut]
    frames: int
    seconds: float
    retries: int
    note: str


def _hex(text: str | int) -> int:
    if isinstance(text, int):
        return text
    try:
        return int(text, 0)
    except ValueError as exc:
        raise ValueError(_("'{text}' is not a number (decimal or 0x hex)").format(text=text)) from exc


class AssignIn(Confirmed):
    vendor: str | int
    product: str | int
    revision: str | int
    serial: str | int
    node_id: int = Field(ge=1, le=127)
    bitrate: int | None = Field(None, description="bit/s from the CiA 305 table; none keeps the device's")
    store: bool = True

    @field_validator("vendor", "product", "revision", "serial")
    @classmethod
    def _number(cls, value: str | int) -> int:
        number = _hex(value)
        if not 0 <= number <= 0xFFFFFFFF:
            raise ValueError(_("{value} does not fit 32 bits").format(value=value))
        return number

    def address(self) -> LssAddress:
        return LssAddress(int(self.vendor), int(self.product), int(self.revision), int(self.serial))


class StepOut(BaseModel):
    step: str
    ok: bool
    text: str


class SwitchIn(Confirmed):
    configuration: bool = False


class ActivateIn(Confirmed):
    bitrate: int
    switch_delay_ms: int = Field(100, ge=1, le=65535)


def device_out(session: SessionDep, address: LssAddress, node_id: int | None = None) -> DeviceOut:
    profile = session.profiles.find_by_identity(address.vendor, address.product)
    return DeviceOut(**address.hex(), device=profile.identity.product_name if profile else None, node_id=node_id)


@router.get("", response_model=FastscanOut)
async def get_found(session: SessionDep) -> FastscanOut:
    """The devices the last fastscan found that were not assigned since."""
    line = lss.line_of(session)
    scan = line.last_scan
    return FastscanOut(devices=[device_out(session, address) for address in line.found],
                       frames=scan.frames if scan else 0, seconds=scan.seconds if scan else 0.0,
                       retries=scan.retries if scan else 0, note=_(lss.MERGE_NOTE))


@router.post("/fastscan", response_model=FastscanOut)
async def fastscan(request: Request, body: FastscanIn, session: SessionDep, ctx: WriteCtxDep) -> FastscanOut:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    result = await lss.fastscan(session, ctx, body.window_ms)
    return FastscanOut(devices=[device_out(session, address) for address in result.found], frames=result.frames,
                       seconds=round(result.seconds, 3), retries=result.retries, note=_(lss.MERGE_NOTE))


@router.post("/assign", response_model=list[StepOut])
async def assign(request: Request, body: AssignIn, session: SessionDep, ctx: WriteCtxDep) -> list[StepOut]:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    steps = await lss.assign(session, ctx, body.address(), body.node_id, bitrate=body.bitrate, store=body.store)
    return [StepOut(**step.__dict__) for step in steps]


@router.post("/switch-global", status_code=204)
async def switch_global(request: Request, body: SwitchIn, session: SessionDep, ctx: WriteCtxDep) -> None:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    await lss.switch_global(session, ctx, body.configuration)


@router.post("/activate-bit-timing", status_code=204)
async def activate_bit_timing(request: Request, body: ActivateIn, session: SessionDep, ctx: WriteCtxDep) -> None:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    await lss.activate_bit_timing(session, ctx, body.bitrate, body.switch_delay_ms)


@router.post("/reset-communication", response_model=list[int])
async def reset_communication(request: Request, body: Confirmed, session: SessionDep, ctx: WriteCtxDep
                              ) -> list[int]:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    return await lss.reset_communication_all(session, ctx)


@router.post("/identify-non-configured")
async def identify_non_configured(session: SessionDep) -> dict[str, bool]:
    """Does any device without a node ID answer? (Identical answers merge: one or many.)"""
    return {"answered": await lss.identify_non_configured(session)}
