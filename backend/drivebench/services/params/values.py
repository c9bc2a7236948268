"""What a read and a write of one parameter answer."""

from __future__ import annotations

from dataclasses import dataclass

from drivebench.device.profiles.scaling import RawValue, ScaledValue


@dataclass(slots=True)
class ParameterValue:
    """One value as read (not frozen: a frozen dataclass costs 3 us to build, a tenth of a read's own work)."""

    ref: str
    name: str
    index: int
    subindex: int
    raw: RawValue
    value: int | float | str | None
    unit: str | None
    text: str | None
    display: str
    read_at: float


@dataclass(frozen=True)
class WriteResult:
    ref: str
    written: ScaledValue
    read_back: ParameterValue | None
    verified: bool | None
    """True: the device reports what was written; False: it differs (see ``mismatch``); None: not read back."""
    mismatch: str | None
    reset_required: bool
