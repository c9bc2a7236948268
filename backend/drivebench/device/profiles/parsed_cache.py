"""Uploaded profiles as parsed before, so a restart does not parse every stored upload again (issue 33: 200 stored
EDS files took 17.6 s before ``/api/health`` answered).

Beside the upload folder (``<folder>.parsed/``, like the ``.names.json`` file) one file per stored file holds the
import warnings (one JSON line) and the parsed profile (its JSON, which pydantic validates in one pass). It is
keyed by a hash of the DriveBench version, the file's name and its bytes: a changed file, a renamed one or a new
release parses again. An entry that cannot be read or does not validate is parsed again too; the upload itself is
always the truth.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivebench import __version__
from drivebench.device.formats.eds import ImportWarning
from drivebench.device.profiles.profile import Profile
from drivebench.i18n import Text

CACHE_SUFFIX = ".parsed"
FORMAT = 1


@dataclass(frozen=True)
class Parsed:
    """What the import made of a file: the profile, its warnings, and whether the file's bytes are kept."""

    profile: Profile
    warnings: list[ImportWarning]
    keeps_original: bool
    suffix: str


def _message_out(message: str) -> object:
    return message.saved() if isinstance(message, Text) else message


def _message_in(data: object) -> str:
    return Text.loaded(data) if isinstance(data, dict) else str(data)


class ParsedCache:
    """The parsed files of one upload folder, in ``<folder>.parsed/``."""

    def __init__(self, upload_dir: Path) -> None:
        self.directory = upload_dir.with_name(upload_dir.name + CACHE_SUFFIX)

    @staticmethod
    def key(name: str, content: bytes) -> str:
        digest = hashlib.sha256(f"{FORMAT}\0{__version__}\0{name}\0".encode())
        digest.update(content)
        return digest.hexdigest()

    def read(self, key: str) -> Parsed | None:
        try:
            head, _newline, profile = (self.directory / f"{key}.json").read_bytes().partition(b"\n")
            data = json.loads(head)
            return Parsed(Profile.model_validate_json(profile),
                          [ImportWarning(**{**w, "message": _message_in(w["message"])}) for w in data["warnings"]],
                          bool(data["keeps_original"]), str(data["suffix"]))
        except (OSError, ValueError, KeyError, TypeError, ValidationError):
            return None

    def write(self, key: str, parsed: Parsed) -> None:
        """Best effort: a folder that cannot be written only means the next start parses again."""
        data: dict[str, Any] = {
            "warnings": [{**vars(w), "message": _message_out(w.message)} for w in parsed.warnings],
            "keeps_original": parsed.keeps_original, "suffix": parsed.suffix}
        with contextlib.suppress(OSError, TypeError, ValueError):
            self.directory.mkdir(parents=True, exist_ok=True)
            handle, temp = tempfile.mkstemp(dir=self.directory, prefix=".entry-")
            try:
                with os.fdopen(handle, "wb") as out:  # a line of warnings, then the profile (pydantic reads it)
                    out.write(json.dumps(data, ensure_ascii=False).encode() + b"\n")
                    out.write(parsed.profile.model_dump_json().encode())
                os.replace(temp, self.directory / f"{key}.json")
            finally:
                Path(temp).unlink(missing_ok=True)

    def keep_only(self, keys: set[str]) -> None:
        """Drop the entries of files no longer stored (deleted or replaced uploads)."""
        if not self.directory.is_dir():
            return
        for path in self.directory.glob("*.json"):
            if path.stem not in keys:
                path.unlink(missing_ok=True)
