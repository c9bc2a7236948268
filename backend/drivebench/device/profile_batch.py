"""Many device descriptions at once: several files, or a .zip of a vendor's EDS/XDD folder.

Each file is checked on its own (one bad file refuses only itself) and the outcome is one row of a summary:
accepted, accepted with warnings, or refused with file, line and reason. A zip is opened with limits checked before
anything is decompressed whole: the number of members, each member's size as read (not as its header claims),
the total, the compression ratio (a zip bomb), and names that leave the archive (``../``, absolute paths).
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Literal

from drivebench.device.loader import PROFILE_SUFFIXES, ProfileRegistry, shown_name
from drivebench.errors import ProfileError

MAX_FILES = 500
MAX_TOTAL_BYTES = 128 * 1024 * 1024
MAX_RATIO = 200
"""Larger expansion than this of a member over 1 MiB is a zip bomb (EDS text packs about 10:1)."""
Outcome = Literal["accepted", "warnings", "refused"]


@dataclass(frozen=True)
class BatchRow:
    file: str
    outcome: Outcome
    profile_id: str | None = None
    warnings: int = 0
    line: int | None = None
    reason: str | None = None


def _member_problem(info: zipfile.ZipInfo, limit: int) -> str | None:
    path = PurePosixPath(info.filename.replace("\\", "/"))
    if path.is_absolute() or ".." in path.parts or (path.parts and ":" in path.parts[0]):
        return "its path leaves the archive (absolute or with '..'): not read"
    if info.file_size > limit:
        return f"it unpacks to {info.file_size} bytes, more than the limit of {limit} for one file"
    if info.file_size > 1024 * 1024 and info.file_size > MAX_RATIO * max(info.compress_size, 1):
        return f"it expands {info.file_size // max(info.compress_size, 1)} times (a zip bomb): not read"
    return None


def unpack_zip(data: bytes, name: str, limit: int) -> tuple[list[tuple[str, bytes]], list[BatchRow]]:
    """The profile files of a zip (name, bytes) and the rows of members refused. Raises ProfileError when the
    archive as a whole cannot be read or passes the limits."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = [i for i in archive.infolist() if not i.is_dir()]
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise ProfileError(f"not a readable zip archive: {exc}", source=name) from exc
    if len(members) > MAX_FILES:
        raise ProfileError(f"the archive holds {len(members)} files; at most {MAX_FILES} are read at once",
                           source=name)
    declared = sum(i.file_size for i in members)
    if declared > MAX_TOTAL_BYTES:
        raise ProfileError(f"the archive unpacks to {declared} bytes, more than {MAX_TOTAL_BYTES}", source=name)
    files: list[tuple[str, bytes]] = []
    refused: list[BatchRow] = []
    total = 0
    for info in members:
        shown = shown_name(info.filename)
        if PurePosixPath(shown).suffix.lower() not in PROFILE_SUFFIXES:
            continue  # readme.txt, pictures: not a device description
        problem = _member_problem(info, limit)
        if problem is not None:
            refused.append(BatchRow(f"{name}/{info.filename}", "refused", reason=problem))
            continue
        try:
            with archive.open(info) as member:
                content = member.read(limit + 1)  # as read, whatever the header claims
        except (zipfile.BadZipFile, OSError, ValueError, NotImplementedError) as exc:
            refused.append(BatchRow(f"{name}/{info.filename}", "refused", reason=f"cannot unpack: {exc}"))
            continue
        total += len(content)
        if len(content) > limit or total > MAX_TOTAL_BYTES:
            refused.append(BatchRow(f"{name}/{info.filename}", "refused",
                                    reason=f"it unpacks to more than the limit of {limit} bytes"))
            continue
        files.append((shown, content))
    return files, refused


def add_many(registry: ProfileRegistry, uploads: list[tuple[str, bytes]]) -> list[BatchRow]:
    """Store every upload that loads (zips unpacked first); one row per file, in order."""
    rows: list[BatchRow] = []
    files: list[tuple[str, bytes]] = []
    for name, content in uploads:
        if name.lower().endswith(".zip"):
            try:
                unpacked, refused = unpack_zip(content, name, registry.max_upload_bytes)
            except ProfileError as exc:
                rows.append(BatchRow(name, "refused", line=exc.line, reason=exc.detail.removeprefix(f"{name}: ")))
                continue
            files += unpacked
            rows += refused
        else:
            files.append((name, content))
    if len(files) > MAX_FILES:
        raise ProfileError(f"{len(files)} files sent; at most {MAX_FILES} are read at once")
    for name, content in files:
        try:
            profile = registry.add_upload(name, content)
        except ProfileError as exc:
            where = f"{exc.source}:{exc.line}: " if exc.source and exc.line else (f"{exc.source}: " if exc.source
                                                                                 else "")
            rows.append(BatchRow(name, "refused", line=exc.line, reason=exc.detail.removeprefix(where)))
            continue
        count = len(registry.loaded(profile.id).warnings)
        rows.append(BatchRow(name, "warnings" if count else "accepted", profile.id, count))
    return rows
