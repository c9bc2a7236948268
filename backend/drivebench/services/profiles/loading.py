"""Stored uploads load in a worker thread after the server listens (issue 33): what waits for them, never
holding the event loop, and how far they are."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Literal

from pydantic import BaseModel

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.i18n import _


class ProfilesLoading(BaseModel):
    """``loading`` while stored uploads are still being read, then ``loaded``."""

    state: Literal["loading", "loaded"]
    loaded: int
    """Stored upload files read so far (a file that does not load counts: it is in the load errors)."""
    stored: int


def progress(registry: ProfileRegistry) -> ProfilesLoading:
    read, stored = registry.upload_progress()
    return ProfilesLoading(state="loaded" if registry.uploads_done.is_set() else "loading", loaded=read,
                           stored=stored)


def progress_line(registry: ProfileRegistry) -> str | None:
    """``loading stored profiles: 120 of 200`` while they load, else None."""
    if registry.uploads_done.is_set():
        return None
    read, stored = registry.upload_progress()
    return _("loading stored profiles: {loaded} of {stored}").format(loaded=read, stored=stored)


async def uploads_loaded(registry: ProfileRegistry) -> None:
    """Wait until every stored upload is read (at once when they are); a loading not begun yet begins now."""
    if not registry.uploads_done.is_set():
        registry.begin_uploads()
        await asyncio.to_thread(registry.uploads_done.wait)


async def profiles_known(registry: ProfileRegistry, profile_ids: Iterable[str | None]) -> None:
    """Wait for the stored uploads only when one of ``profile_ids`` is not known yet (a shipped profile never
    waits); an id that is not there after loading is answered by ``registry.get`` as always."""
    if any(pid and not registry.has(pid) for pid in profile_ids):
        await uploads_loaded(registry)


async def load_in_background(registry: ProfileRegistry) -> None:
    """The stored uploads, read in a worker thread (the lifespan starts this as a task)."""
    await asyncio.to_thread(registry.load_uploads)
