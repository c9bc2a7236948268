"""Units of a CiA 402 drive's position and velocity values, as the drive states them.

CiA 402-2: position values (0x607A, 0x6064, 0x60F4, 0x607D …) are in the drive's position units, velocities
(0x60FF, 0x606C, 0x6081, 0x607F …) in its velocity units. Their names come from the SI unit objects 0x60A8 / 0x60A9
where the device has them; else from the factor group (0x608F encoder resolution, 0x6091 gear ratio, 0x6092 feed
constant: one position unit is that many increments); else the values are raw increments, and the panel says so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from drivebench.device.drive import cia402
from drivebench.errors import DriveBenchError, UnknownParameter
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params import reads

UNITS_TTL_S = 5.0


@dataclass(frozen=True)
class Units:
    position: str
    velocity: str
    how: str
    """Where the names come from (0x60A8/0x60A9, the factor group, or nothing: increments)."""

    def of(self, ref: str) -> str | None:
        kind = cia402.UNIT_KIND.get(ref)
        return self.position if kind == "position" else self.velocity if kind == "velocity" else None


def _has(node: SessionNode, ref: str) -> bool:
    if node.catalog is None:
        return False
    try:
        node.catalog.resolve(ref)
    except UnknownParameter:
        return False
    return True


async def _int(session: Session, node: SessionNode, ref: str) -> int | None:
    if not _has(node, ref):
        return None
    try:
        raw = (await reads.read(session, node.node_id, ref)).raw
    except DriveBenchError:
        return None
    return int(raw) if isinstance(raw, int) else None


async def _ratio(session: Session, node: SessionNode, index: str) -> float | None:
    top, bottom = await _int(session, node, f"{index}.1"), await _int(session, node, f"{index}.2")
    return top / bottom if top and bottom else None


async def _units_read(session: Session, node: SessionNode) -> _Read:
    """What the unit objects said (kept on the node for :data:`UNITS_TTL_S`)."""
    cached: tuple[float, _Read] | None = getattr(node, "_motion_units", None)  # kept on the node, as its catalog
    if cached is None or time.monotonic() - cached[0] >= UNITS_TTL_S:
        cached = time.monotonic(), await _read_units(session, node)
        object.__setattr__(node, "_motion_units", cached)
    return cached[1]


async def motion_units(session: Session, node: SessionNode) -> Units:
    """The units, named in the reader's language."""
    position, velocity, per_unit = await _units_read(session, node)
    if position is not None:
        return Units(position, velocity or f"{position}/s", _("SI unit objects 0x60A8/0x60A9"))
    if per_unit is not None:
        return Units(_("position units ({count} increments)").format(count=f"{per_unit:g}"),
                     velocity or _("position units/s"), _("factor group 0x608F/0x6091/0x6092"))
    return Units(_("increments"), velocity or _("increments/s"),
                 _("no SI unit objects or factor group: raw increments"))


_Read = tuple[str | None, str | None, float | None]
"""Position unit and velocity unit from 0x60A8/0x60A9, position units per increment from the factor group."""


async def _read_units(session: Session, node: SessionNode) -> _Read:
    position_code = await _int(session, node, cia402.SI_UNIT_POSITION)
    velocity_code = await _int(session, node, cia402.SI_UNIT_VELOCITY)
    position = cia402.si_unit(position_code) if position_code is not None else None
    velocity = cia402.si_unit(velocity_code) if velocity_code is not None else None
    if position is not None:
        return position, velocity, None
    encoder = await _ratio(session, node, cia402.POSITION_ENCODER_RESOLUTION)
    gear = await _ratio(session, node, cia402.GEAR_RATIO) or 1.0
    feed = await _ratio(session, node, cia402.FEED_CONSTANT)
    return None, velocity, encoder * gear / feed if encoder and feed else None


async def position_per_velocity(session: Session, node: SessionNode) -> float:
    """Position units per second in one velocity unit: a drive whose 0x60A9 says rpm turns one revolution (360 °,
    else the feed constant 0x6092) per minute and rpm; else CiA 402's velocity unit, one position unit per second."""
    position, velocity, _per_unit = await _units_read(session, node)
    if velocity != "rpm":
        return 1.0
    per_revolution = 360.0 if position == "°" else await _ratio(session, node, cia402.FEED_CONSTANT)
    return per_revolution / 60 if per_revolution else 1.0


async def generic_limits(session: Session, node: SessionNode, ref: str) -> tuple[float | None, float | None]:
    """Range of a CiA 402 setpoint: software position limits 0x607D (0/0: none) for a position, ± 0x607F max
    profile velocity, ± 0x6072 max torque (‰, else ±1000 ‰)."""
    if ref in (cia402.TARGET_POSITION, cia402.INTERPOLATION_DATA_RECORD):  # both positions
        low, high = await _int(session, node, cia402.MIN_POSITION_LIMIT), await _int(session, node,
                                                                                     cia402.MAX_POSITION_LIMIT)
        if low is None or high is None or low == high == 0:
            return None, None
        return float(low), float(high)
    if ref == cia402.TARGET_VELOCITY:
        top = await _int(session, node, cia402.MAX_PROFILE_VELOCITY)
        return (-float(top), float(top)) if top else (None, None)
    if ref == cia402.TARGET_TORQUE:
        top = await _int(session, node, cia402.MAX_TORQUE)
        return -float(top or 1000), float(top or 1000)
    return None, None
