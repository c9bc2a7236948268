"""The comparison with the factory setting (STARTER's and Engineer's parameter comparison): which settings of a
node differ from the values it holds from the factory (:mod:`drivebench.device.profiles.factory_default`).

Only settings take part: readable and writable entries that are not process data or volatile (a control word or
a setpoint has no factory value worth comparing). A setting whose profile gives no factory value is listed apart,
never compared with a guess. Values come from the device (all, or those not read yet) or from the last read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.factory_default import factory_raw, same_raw
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import DriveBenchError
from drivebench.services.bus.sessions import Session
from drivebench.services.params import lookup, reads, session_part
from drivebench.services.params.values import ParameterValue


class Reading(StrEnum):
    ALL = "all"
    """Read every setting from the device now."""
    MISSING = "missing"
    """Read only the settings not read yet; the others as last read."""
    NONE = "none"
    """Compare the values last read; settings never read are listed as not read."""


@dataclass(frozen=True)
class Compared:
    item: Item
    value: ParameterValue | None
    factory: ParameterValue | None
    problem: str | None = None
    """Why the value could not be read (or was never read)."""


@dataclass
class Comparison:
    node_id: int
    device: str
    changed: list[Compared] = field(default_factory=list)
    no_factory_value: list[Compared] = field(default_factory=list)
    not_read: list[Compared] = field(default_factory=list)
    same: int = 0


def factory_value(item: Item, node_id: int) -> ParameterValue | None:
    """The factory value as a value read is held (the page words it in the reader's language); None: no source
    gives one."""
    raw = factory_raw(item.entry, node_id, item.index, item.subindex)
    if raw is None:
        return None
    scaled = from_raw(item.entry, raw)
    value = scaled.value.hex(" ") if isinstance(scaled.value, bytes) else scaled.value
    return ParameterValue(item.ref, item.name, item.index, item.subindex, scaled.raw, value, scaled.unit,
                          scaled.text, reads.display(item, scaled), 0.0)


def factory_shown(item: Item, node_id: int) -> str | None:
    """The factory value as the API shows a value (``10.20 A``, ``0x00000185``); None: no source gives one."""
    found = factory_value(item, node_id)
    return None if found is None else found.display


def settings_of(items: list[Item]) -> list[Item]:
    return [item for item in items
            if item.entry.access.readable and item.entry.access.writable and item.entry.live is None]


async def compare(session: Session, node_id: int, reading: Reading = Reading.MISSING) -> Comparison:
    node = session.node(node_id)
    settings = settings_of(lookup.items(node))
    last = session_part.service(session).values.get(node_id, {})
    wanted = [item.ref for item in settings if reading is Reading.ALL or
              (reading is Reading.MISSING and item.ref not in last)]
    errors: dict[str, str] = {}
    for start in range(0, len(wanted), reads.MAX_BATCH):
        chunk = wanted[start:start + reads.MAX_BATCH]
        for ref, result in zip(chunk, await reads.read_many(session, node_id, chunk), strict=True):
            if isinstance(result, DriveBenchError):
                errors[ref] = result.shown_detail()
    last = session_part.service(session).values.get(node_id, {})
    found = Comparison(node_id, node.device_name)
    for item in settings:
        value = None if item.ref in errors else last.get(item.ref)
        factory = factory_value(item, node_id)
        if value is None:
            found.not_read.append(Compared(item, None, factory, errors.get(item.ref)))
        elif factory is None:
            found.no_factory_value.append(Compared(item, value, None))
        elif same_raw(value.raw, factory.raw):
            found.same += 1
        else:
            found.changed.append(Compared(item, value, factory))
    return found
