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

from drivebench.device.profiles.loader import PROFILE_SUFFIXES, ProfileRegistry, shown_name
from drivebench.errors import ProfileError
from drivebench.i18n import _, shown

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
        return _("its path leaves the archive (absolute or with '..'): not read")
    if info.file_size > limit:
        return _("it unpacks to {size} bytes, more than the limit of {limit} for one file").format(
            size=info.file_size, limit=limit)
    if info.file_size > 1024 * 1024 and info.file_size > MAX_RATIO * max(info.compress_size, 1):
        return _("it expands {ratio} times (a zip bomb): not read").format(
            ratio=info.file_size // max(info.compress_size, 1))
    return None


def unpack_zip(data: bytes, name: str, limit: int) -> tuple[list[tuple[str, bytes, str]], list[BatchRow]]:
    """The profile files of a zip (name, bytes, the row's name: ``archive.zip/folder/member.eds``) and the rows of
    members refused. Raises ProfileError when the archive as a whole cannot be read or passes the limits."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = [i for i in archive.infolist() if not i.is_dir()]
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise ProfileError(_("not a readable zip archive: {reason}").format(reason=exc), source=name) from exc
    if len(members) > MAX_FILES:
        raise ProfileError(_("the archive holds {count} files; at most {limit} are read at once").format(
            count=len(members), limit=MAX_FILES), source=name)
    declared = sum(i.file_size for i in members)
    if declared > MAX_TOTAL_BYTES:
        raise ProfileError(_("the archive unpacks to {size} bytes, more than {limit}").format(
            size=declared, limit=MAX_TOTAL_BYTES), source=name)
    files: list[tuple[str, bytes, str]] = []
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
            refused.append(BatchRow(f"{name}/{info.filename}", "refused",
                                    reason=_("cannot unpack: {reason}").format(reason=exc)))
            continue
        total += len(content)
        if len(content) > limit or total > MAX_TOTAL_BYTES:
            refused.append(BatchRow(f"{name}/{info.filename}", "refused",
                                    reason=_("it unpacks to more than the limit of {limit} bytes").format(
                                        limit=limit)))
            continue
        files.append((shown, content, f"{name}/{info.filename}"))
    return files, refused


def add_many(registry: ProfileRegistry, uploads: list[tuple[str, bytes]]) -> list[BatchRow]:
    """Store every upload that loads (zips unpacked first); one row per file, in order."""
    rows: list[BatchRow] = []
    files: list[tuple[str, bytes, str]] = []
    for name, content in uploads:
        if name.lower().endswith(".zip"):
            try:
                unpacked, refused = unpack_zip(content, name, registry.max_upload_bytes)
            except ProfileError as exc:
                rows.append(BatchRow(name, "refused", line=exc.line, reason=shown(exc.reason)))
                continue
            files += unpacked
            rows += refused
        else:
            files.append((name, content, name))
    if len(files) > MAX_FILES:
        raise ProfileError(_("{count} files sent; at most {limit} are read at once").format(count=len(files),
                                                                                         limit=MAX_FILES))
    for name, content, row_name in files:  # a zip member's row names the archive and the member's path in it
        try:
            profile = registry.add_upload(name, content)
        except ProfileError as exc:
            rows.append(BatchRow(row_name, "refused", line=exc.line, reason=shown(exc.reason)))
            continue
        count = len(registry.loaded(profile.id).warnings)
        rows.append(BatchRow(row_name, "warnings" if count else "accepted", profile.id, count))
    return rows
