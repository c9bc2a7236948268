"""Line addressing (LSS, CiA 305) on a session's bus: fastscan, assign a node ID to a found device, and the steps
that reach every device (confirmation naming ``all``, refused while a node is enabled or armed)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field, field_validator

from drivebench.device.profiles.profile import Profile
from drivebench.i18n import _
from drivebench.protocol.canopen.lss import LssAddress
from drivebench.services.lss import bit_rate
from drivebench.services.lss import line as lss
from drivebench.services.lss.identify import identify
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import SessionDep, StateDep
from drivebench.web.safety import WriteCtxDep, confirmation

router = APIRouter(route_class=DeferredRoute, prefix="/api/sessions/{session_id}/lss", tags=["lss"])


class Confirmed(BaseModel):
    confirm: str | int | None = Field(None, description="'all' (these steps reach every device on the bus), or the "
                                                        "X-DriveBench-Confirm header")
    confirm_values: dict[str, Any] | None = Field(None, description="the values the 428 named, repeated")


class FastscanIn(Confirmed):
    window_ms: float = Field(50, description="how long an answer is waited for (the fastscan narrows it to a few "
                                             "times the answer time it measures)")


class CandidateOut(BaseModel):
    id: str
    name: str
    product_code: str | None = Field(None, description="none: the profile carries no product code")


class DeviceOut(BaseModel):
    vendor: str
    product: str
    revision: str
    serial: str
    device: str | None = Field(None, description="the profile the vendor ID and product code match, if any")
    profile: str | None = Field(None, description="that profile's id")
    vendor_name: str | None = Field(None, description="from the profiles with this vendor ID")
    candidates: list[CandidateOut] = Field(default_factory=list, description="profiles of this vendor ID, when "
                                                                             "none matches the product code")
    identified: str = Field("", description="what the answer tells, in words")
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


def _number(value: str | int) -> int:
    number = _hex(value)
    if not 0 <= number <= 0xFFFFFFFF:
        raise ValueError(_("{value} does not fit 32 bits").format(value=value))
    return number


class AddressIn(BaseModel):
    vendor: str | int
    product: str | int
    revision: str | int
    serial: str | int

    @field_validator("vendor", "product", "revision", "serial")
    @classmethod
    def _number(cls, value: str | int) -> int:
        return _number(value)

    def address(self) -> LssAddress:
        return LssAddress(int(self.vendor), int(self.product), int(self.revision), int(self.serial))


class AssignIn(AddressIn, Confirmed):
    node_id: int = Field(ge=1, le=127)
    bitrate: int | None = Field(None, description="bit/s from the CiA 305 table; none keeps the device's")
    store: bool = True


class IdentifyIn(BaseModel):
    vendor: str | int
    product: str | int
    revision_low: str | int = 0
    revision_high: str | int = 0xFFFFFFFF
    serial_low: str | int = 0
    serial_high: str | int = 0xFFFFFFFF

    @field_validator("vendor", "product", "revision_low", "revision_high", "serial_low", "serial_high")
    @classmethod
    def _number(cls, value: str | int) -> int:
        return _number(value)


class IdentifyOut(BaseModel):
    answered: bool
    text: str


class InquireIn(BaseModel):
    select: AddressIn | None = Field(None, description="switch this device to configuration state first (switch "
                                                       "state selective); none: the device that is in it")


class InquireOut(DeviceOut):
    active_node_id: int | None = Field(None, description="its active node ID; none: it has none (255)")
    text: str


class StepOut(BaseModel):
    step: str
    ok: bool
    text: str


class SwitchIn(Confirmed):
    configuration: bool = False


class ActivateIn(Confirmed):
    bitrate: int
    switch_delay_ms: int = Field(100, ge=1, le=65535)
    configuration_first: bool = Field(False, description="switch state global (configuration) first, so every "
                                                         "device switches, and (waiting) at the new rate after")


def device_out(profiles: list[Profile], address: LssAddress, node_id: int | None = None) -> DeviceOut:
    known = identify(profiles, address)
    candidates = [CandidateOut(id=candidate.id, name=candidate.name, product_code=None
                               if candidate.product_code is None else f"0x{candidate.product_code:08X}")
                  for candidate in known.candidates]
    return DeviceOut(**address.hex(), device=known.device, profile=known.profile, vendor_name=known.vendor_name,
                     candidates=candidates, identified=known.text, node_id=node_id)


@router.get("", response_model=FastscanOut)
async def get_found(session: SessionDep, state: StateDep) -> FastscanOut:
    """The devices the last fastscan found that were not assigned since."""
    line = lss.line_of(session)
    scan = line.last_scan
    profiles = state.registry.all()
    return FastscanOut(devices=[device_out(profiles, address) for address in line.found],
                       frames=scan.frames if scan else 0, seconds=scan.seconds if scan else 0.0,
                       retries=scan.retries if scan else 0, note=_(lss.MERGE_NOTE))


@router.post("/fastscan", response_model=FastscanOut)
async def fastscan(request: Request, body: FastscanIn, session: SessionDep, ctx: WriteCtxDep, state: StateDep
                   ) -> FastscanOut:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    result = await lss.fastscan(session, ctx, body.window_ms)
    profiles = state.registry.all()
    return FastscanOut(devices=[device_out(profiles, address) for address in result.found], frames=result.frames,
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


class BehindOut(DeviceOut):
    at_old_rate: bool = Field(description="it still answers at the old bit rate (it ignored the switch); false: "
                                          "at neither rate")


class BitRateSwitchOut(BaseModel):
    bitrate: int
    old_bitrate: int
    adapter_bitrate: int = Field(description="the bit rate the session's adapter runs at afterwards")
    checked: int = Field(description="devices known by their LSS address (found, assigned) asked afterwards")
    followed: list[DeviceOut] = Field(description="those that answer at the new bit rate")
    left_behind: list[BehindOut] = Field(description="those that do not answer at the new bit rate")
    nodes_followed: list[int] = Field(description="the session's other nodes that answer an SDO read at the new rate")
    nodes_silent: list[int] = Field(description="the session's other nodes that do not")
    text: str


@router.post("/activate-bit-timing", response_model=BitRateSwitchOut)
async def activate_bit_timing(request: Request, body: ActivateIn, session: SessionDep, ctx: WriteCtxDep,
                              state: StateDep) -> BitRateSwitchOut:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    switch = await bit_rate.activate_bit_timing(session, ctx, body.bitrate, body.switch_delay_ms,
                                                configuration_first=body.configuration_first)
    profiles = state.registry.all()
    left = [BehindOut(**device_out(profiles, entry.address).model_dump(), at_old_rate=entry.at_old_rate)
            for entry in switch.left_behind]
    return BitRateSwitchOut(bitrate=switch.bitrate, old_bitrate=switch.old_bitrate,
                            adapter_bitrate=switch.adapter_bitrate, checked=switch.checked,
                            followed=[device_out(profiles, address) for address in switch.followed],
                            left_behind=left, nodes_followed=switch.nodes_followed, nodes_silent=switch.nodes_silent,
                            text=switch.text)


@router.post("/reset-communication", response_model=list[int])
async def reset_communication(request: Request, body: Confirmed, session: SessionDep, ctx: WriteCtxDep
                              ) -> list[int]:
    ctx = ctx.confirming(confirmation(request, body.confirm, body.confirm_values))
    return await lss.reset_communication_all(session, ctx)


@router.post("/identify-non-configured")
async def identify_non_configured(session: SessionDep) -> dict[str, bool]:
    """Does any device without a node ID answer? (Identical answers merge: one or many.)"""
    return {"answered": await lss.identify_non_configured(session)}


@router.post("/identify-remote", response_model=IdentifyOut)
async def identify_remote(body: IdentifyIn, session: SessionDep) -> IdentifyOut:
    """Identify remote slave (0x46-0x4B): does a device with this vendor and product, and revision and serial in
    the ranges, answer? Read-only (no state changes): no confirmation."""
    vendor, product = int(body.vendor), int(body.product)
    revisions, serials = (int(body.revision_low), int(body.revision_high)), (int(body.serial_low),
                                                                              int(body.serial_high))
    answered = await lss.identify_remote(session, vendor, product, revisions, serials)
    what = _("vendor {vendor}, product {product}, revision {rev_low} ... {rev_high}, serial {ser_low} ... "
             "{ser_high}").format(vendor=f"0x{vendor:08X}", product=f"0x{product:08X}",
                                  rev_low=f"0x{revisions[0]:08X}", rev_high=f"0x{revisions[1]:08X}",
                                  ser_low=f"0x{serials[0]:08X}", ser_high=f"0x{serials[1]:08X}")
    text = (_("At least one device with {what} answered (identical answers merge: one or several).") if answered
            else _("No device with {what} answered: none is on this bus, or it runs at another bit rate.")
            ).format(what=what)
    return IdentifyOut(answered=answered, text=text)


@router.post("/inquire", response_model=InquireOut)
async def inquire(body: InquireIn, session: SessionDep, state: StateDep) -> InquireOut:
    """Inquire identity and node ID (0x5A-0x5E) of the device in LSS configuration state; ``select`` switches one
    device there first (switch state selective reaches that device only and changes nothing it runs: no
    confirmation). It stays in configuration state until a switch state global (waiting)."""
    inquiry = await lss.inquire(session, body.select.address() if body.select else None)
    device = device_out(state.registry.all(), inquiry.address)
    node = None if inquiry.node_id == 0xFF else inquiry.node_id
    text = (_("Active node ID {node}.").format(node=node) if node is not None
            else _("It has no node ID (255)."))
    if inquiry.selected:
        text += " " + _("The device stays in LSS configuration state until a switch state global (waiting).")
    return InquireOut(**device.model_dump(), active_node_id=node, text=text)
