"""Storing and deleting uploaded profiles: one file (checked, stored as ``<id>.<suffix>``), many files or zips
(each accepted or refused on its own), delete (only uploads, only when no open session's node uses it)."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Literal

from pydantic import BaseModel

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.device.profiles.profile import Profile
from drivebench.device.profiles.profile_batch import add_many
from drivebench.errors import Conflict, ProfileError
from drivebench.i18n import N_, _
from drivebench.services.bus.sessions import Session


class UploadTooLarge(ProfileError):
    """An upload past the size limit: answered with 413 (Content Too Large), not 422."""

    title = N_("Upload too large")


class BatchRowOut(BaseModel):
    """One file of a many-file upload: accepted, accepted with warnings, or refused (line and reason)."""

    file: str
    outcome: Literal["accepted", "warnings", "refused"]
    profile_id: str | None
    warnings: int
    line: int | None
    reason: str | None


class BatchResult(BaseModel):
    accepted: int
    with_warnings: int
    refused: int
    rows: list[BatchRowOut]


def size_text(count: int) -> str:
    return f"{count / 1024 / 1024:.1f} MiB" if count >= 1024 * 1024 else f"{count / 1024:.0f} KiB"


def store_upload(registry: ProfileRegistry, name: str, content: bytes) -> Profile:
    """Check and store one uploaded file; a bad file changes nothing (blocking: run it in a thread)."""
    if name.lower().endswith(".json"):
        _check_utf8(content, name)
    return registry.add_upload(name, content)


def store_many(registry: ProfileRegistry, uploads: list[tuple[str, bytes]]) -> BatchResult:
    """Store several files or zips; each file is accepted or refused on its own (blocking: run it in a thread)."""
    out = [BatchRowOut(**vars(row)) for row in add_many(registry, uploads)]
    return BatchResult(accepted=sum(r.outcome == "accepted" for r in out),
                       with_warnings=sum(r.outcome == "warnings" for r in out),
                       refused=sum(r.outcome == "refused" for r in out), rows=out)


def _check_utf8(content: bytes, name: str) -> None:
    """JSON must be UTF-8: name the line of the first bad byte (pydantic only says 'invalid unicode')."""
    try:
        content.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = content.count(b"\n", 0, exc.start) + 1
        raise ProfileError(_("not UTF-8 text: byte {byte} cannot be decoded").format(
            byte=f"0x{content[exc.start]:02X}"), source=name, line=line) from exc


def users_of(sessions: Iterable[Session], profile_id: str) -> list[str]:
    """Nodes of open sessions handled with this profile (``node 5 of 'Demo plant'``)."""
    return [_("node {node} of '{session}'").format(node=node_id, session=session.name)
            for session in sessions
            for node_id, node in session.nodes.items() if node.profile is not None and node.profile.id == profile_id]


async def delete_upload(registry: ProfileRegistry, sessions: Iterable[Session], profile_id: str) -> None:
    """Delete an uploaded profile: a built-in one or one a node of an open session uses is a Conflict."""
    registry.get(profile_id)
    if registry.is_builtin(profile_id):
        raise Conflict(_("'{profile}' is a built-in profile (device_profiles/); only uploaded profiles can be "
                         "deleted").format(profile=profile_id))
    in_use = users_of(sessions, profile_id)
    if in_use:
        raise Conflict(_("'{profile}' is in use by {nodes}; remove those nodes first").format(
            profile=profile_id, nodes=", ".join(in_use)))
    await asyncio.to_thread(registry.remove_upload, profile_id)
