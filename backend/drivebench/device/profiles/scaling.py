"""Engineering value <-> raw value, with validation before anything is sent."""

from __future__ import annotations

import math
from dataclasses import dataclass

from drivebench.device.profiles.profile import Access, Entry
from drivebench.errors import InvalidValue, OutOfRange, ReadOnly
from drivebench.i18n import _
from drivebench.protocol.datatypes import DataType

RawValue = int | float | str | bytes


@dataclass(frozen=True)
class ScaledValue:
    raw: RawValue
    value: int | float | str | None
    unit: str | None
    text: str | None
    """Selection-list meaning, or named set bits; None where the value speaks for itself."""

    def display(self) -> str:
        if self.text is not None and isinstance(self.raw, int) and not isinstance(self.raw, bool):
            return f"{self.raw} = {self.text}"
        if isinstance(self.value, bytes):
            return self.value.hex(" ")
        return f"{self.value} {self.unit}".strip() if self.unit else f"{self.value}"


def _limits_text(entry: Entry) -> str:
    unit = f" {entry.unit}" if entry.unit else ""
    low = "-inf" if entry.min is None else format_value(entry, entry.min)
    high = "+inf" if entry.max is None else format_value(entry, entry.max)
    return f"{low} ... {high}{unit}"


def format_value(entry: Entry, value: float | int) -> str:
    if entry.decimals == 0:
        return str(int(value)) if float(value).is_integer() else str(value)
    return f"{value:.{entry.decimals}f}"


def from_raw(entry: Entry, raw: RawValue) -> ScaledValue:
    """What the device sent -> what a user reads (C00088: raw 1020 -> 10.20 A)."""
    if isinstance(raw, (str, bytes)):
        text_value = raw if isinstance(raw, str) else raw.hex(" ")
        return ScaledValue(raw.hex() if isinstance(raw, bytes) else raw, text_value, entry.unit, None)
    value: int | float
    if entry.factor == 1:
        value = raw
    else:
        value = round(raw / entry.factor, entry.decimals + 2)
        if entry.decimals:
            value = round(value, entry.decimals)
    text = None
    if isinstance(raw, int) and entry.selection:
        text = entry.selection.get(raw, _("(not in the selection list)"))
    elif isinstance(raw, int) and entry.bits:
        set_bits = [name for bit, name in sorted(entry.bits.items()) if raw >> bit & 1]
        text = ", ".join(set_bits) if set_bits else _("no bit set")
    return ScaledValue(raw, value, entry.unit, text)


def to_raw(entry: Entry, value: object, *, ref: str = "") -> RawValue:
    """What a user typed -> raw value to send, or a ParameterError naming the parameter, range and unit."""
    label = f"{ref} ({entry.name})" if ref else entry.name
    if not entry.access.writable:
        raise ReadOnly(_("{label} is read-only").format(label=label))
    dt = entry.data_type
    if dt.is_string:
        if dt is DataType.VISIBLE_STRING:
            return str(value)
        if isinstance(value, str):
            try:
                return bytes.fromhex(value)
            except ValueError as exc:
                raise InvalidValue(_("{label} expects hex bytes such as '01 02 0A'").format(label=label)) from exc
        raise InvalidValue(_("{label} expects hex bytes").format(label=label))
    if isinstance(value, str):
        value = _parse_number_or_selection(entry, value, label)
    if not isinstance(value, (int, float)) or (isinstance(value, bool) and dt is not DataType.BOOLEAN):
        raise InvalidValue(_("{label} expects a number, got {value}").format(label=label, value=repr(value)))
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidValue(_("{label} expects a finite number").format(label=label))
    if (entry.min is not None and value < entry.min) or (entry.max is not None and value > entry.max):
        raise OutOfRange(_("{label}: {value} is outside the allowed range {limits}").format(
            label=label, value=value, limits=_limits_text(entry)))
    if dt.is_float:
        return float(value) * float(entry.factor)
    scaled = value * entry.factor
    raw = round(scaled)
    if abs(scaled - raw) > 1e-6 * max(1.0, abs(scaled)):
        step = 1 / entry.factor
        raise InvalidValue(_("{label}: {value} has more decimals than the device resolves (step {step})").format(
            label=label, value=value, step=f"{step:g}{' ' + entry.unit if entry.unit else ''}"))
    limits = dt.raw_limits()
    if limits and not limits[0] <= raw <= limits[1]:
        raise OutOfRange(_("{label}: {value} does not fit the data type {type} (raw {low} ... {high})").format(
            label=label, value=value, type=dt.value, low=limits[0], high=limits[1]))
    if entry.selection and raw not in entry.selection:
        allowed = ", ".join(f"{k} = {v}" for k, v in sorted(entry.selection.items()))
        raise OutOfRange(_("{label}: {raw} is not in the selection list ({allowed})").format(
            label=label, raw=raw, allowed=allowed))
    return raw


def _parse_number_or_selection(entry: Entry, text: str, label: str) -> int | float:
    cleaned = text.strip()
    if entry.unit and cleaned.endswith(entry.unit):
        cleaned = cleaned[: -len(entry.unit)].strip()
    for raw, meaning in entry.selection.items():
        if cleaned.lower() == meaning.lower():
            return raw / entry.factor if entry.factor != 1 else raw
    try:
        if cleaned.lower().startswith(("0x", "0b")):
            return int(cleaned, 0)
        number = float(cleaned.replace(",", "."))
    except ValueError as exc:
        raise InvalidValue(_("{label} expects a number, got '{text}'").format(label=label, text=text)) from exc
    return int(number) if number.is_integer() and entry.factor == 1 else number


def is_writable(entry: Entry) -> bool:
    return entry.access in (Access.RW, Access.WO, Access.RWR, Access.RWW)
