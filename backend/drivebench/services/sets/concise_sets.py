"""Concise DCF (CiA 302-3) of a parameter set: generated, shown decoded, downloaded.

Downloaded in one transfer to 0x1F22 sub <node> where the node's profile lists that object (a CiA 302 master
object), else entry by entry through the one checked write path (:func:`writes.write`: range check, the node's
lease, audit origin ``concise-dcf``; values that can move the drive need the confirmation that names them, asked
for before anything is sent).
"""

from __future__ import annotations

import base64
from collections.abc import Mapping

from pydantic import BaseModel

from drivebench.device.drive.motion import moves
from drivebench.device.formats.concise_dcf import ConciseEntry, decode, encode
from drivebench.device.profiles.catalog import Item
from drivebench.device.profiles.catalog_cache import catalog_for
from drivebench.device.profiles.profile import Profile
from drivebench.device.profiles.scaling import from_raw
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.protocol.datatypes import decode as decode_value
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.params import node_lease, reads, writes
from drivebench.services.params.jobs import said
from drivebench.services.params.write_context import WriteContext
from drivebench.services.sets.parameter_sets import Raw, engineering
from drivebench.services.sets.set_jobs import download_order

ORIGIN = "concise-dcf"
CONCISE_DCF_INDEX = 0x1F22


class ConciseLine(BaseModel):
    index: int
    subindex: int
    ref: str
    name: str
    size: int
    data: str
    """The entry's bytes, hex."""
    value: str
    """As the Parameters tab shows it."""


class ConcisePreview(BaseModel):
    node_id: int
    count: int
    size: int
    lines: list[ConciseLine]
    base64: str
    """The whole concise DCF (what a download sends, or a file of it)."""


def _item(profile: Profile, ref: str) -> Item:
    return catalog_for(profile).resolve(ref)


def entries_of(profile: Profile, values: Mapping[str, Raw]) -> list[tuple[Item, Raw, ConciseEntry]]:
    """The set's values as concise DCF entries, in the download's dependency-safe order."""
    found = []
    for ref in download_order(profile, list(values)):
        item = _item(profile, ref)
        raw = values[ref]
        found.append((item, raw, ConciseEntry(item.index, item.subindex,
                                              writes.encoded(item, raw, engineering(item, raw)))))
    return found


def _line(profile: Profile | None, entry: ConciseEntry) -> ConciseLine:
    item = catalog_for(profile).by_address(entry.index, entry.subindex) if profile is not None else None
    ref = f"0x{entry.index:04X}" if entry.subindex == 0 else f"0x{entry.index:04X}.{entry.subindex}"
    if item is None:
        return ConciseLine(index=entry.index, subindex=entry.subindex, ref=ref, name=_("(not in the profile)"),
                           size=len(entry.data), data=entry.data.hex(" "), value=entry.data.hex(" "))
    try:
        shown = reads.display(item, from_raw(item.entry, decode_value(item.entry.data_type, entry.data)))
    except (ValueError, UnicodeDecodeError, DriveBenchError):
        shown = entry.data.hex(" ")
    return ConciseLine(index=entry.index, subindex=entry.subindex, ref=item.ref, name=item.name,
                       size=len(entry.data), data=entry.data.hex(" "), value=shown)


def preview(profile: Profile | None, node_id: int, data: bytes) -> ConcisePreview:
    """A concise DCF decoded (index, sub-index, name, value) as the page shows it before sending."""
    entries = decode(data)
    return ConcisePreview(node_id=node_id, count=len(entries), size=len(data),
                          lines=[_line(profile, entry) for entry in entries], base64=base64.b64encode(data).decode())


def generate(profile: Profile, values: Mapping[str, Raw]) -> bytes:
    return encode(entry for _item, _raw, entry in entries_of(profile, values))


class ConciseResult(BaseModel):
    node_id: int
    transfer: str
    """``0x1F22``: one transfer; ``entries``: one write per entry."""
    written: int
    failed: list[str]
    """One sentence per entry that was not written (the others were)."""


def _confirmed(session: Session, node_id: int, profile: Profile,
               entries: list[tuple[Item, Raw, ConciseEntry]], ctx: WriteContext) -> WriteContext:
    moving = [(item, raw) for item, raw, _entry in entries
              if isinstance(raw, (int, float)) and moves(item, raw, profile) is not None]
    if not moving:
        return ctx
    values = {key: value for item, raw in moving
              for key, value in writes.sent_value(item, engineering(item, raw)).items()}
    what = _("Concise DCF to node {node}: {refs}").format(node=node_id,
                                                            refs=", ".join(item.ref for item, _raw in moving[:4]))
    return drive_guard.confirm_moving(session, node_id, what, values, ctx)[1]


async def download(session: Session, node_id: int, values: Mapping[str, Raw], *, ctx: WriteContext
                   ) -> ConciseResult:
    node = session.node(node_id)
    profile = node.profile
    if profile is None:
        raise InvalidValue(_("Node {node} has no device profile: its values cannot be encoded.").format(node=node_id))
    entries = entries_of(profile, values)
    ctx = _confirmed(session, node_id, profile, entries, ctx).as_origin(ORIGIN)
    if catalog_for(profile).by_address(CONCISE_DCF_INDEX, node_id) is not None:
        data = encode(entry for _item, _raw, entry in entries)
        with node_lease.writing(session, node_id, ctx):
            await writes.send_logged(session, node_id, CONCISE_DCF_INDEX, node_id, data, ctx=ctx)
        return ConciseResult(node_id=node_id, transfer="0x1F22", written=len(entries), failed=[])
    failed: list[str] = []
    for item, raw, _entry in entries:
        try:
            await writes.write(session, node_id, item.ref, engineering(item, raw), ctx=ctx)
        except DriveBenchError as exc:
            failed.append(_("{ref} ({name}): {why}").format(ref=item.ref, name=item.name, why=said(exc)))
    return ConciseResult(node_id=node_id, transfer="entries", written=len(entries) - len(failed), failed=failed)
